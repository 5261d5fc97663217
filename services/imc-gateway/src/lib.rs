//! skymesh imc-gateway: lets an LSTS tool (Neptus, DUNE, any IMC peer) operate
//! skymesh hardware over IMC on UDP.
//!
//! IMC has no authentication: only datagrams from `allowed_peers` (addresses and
//! networks, loopback by default) are read at all; the rest are dropped
//! (`not_allowed`) before decoding.
//!
//! The gateway *translates*: one datagram is one IMC message, decoded and checked
//! with the `imc-proto` codec; what is valid and addressed to us becomes a bus
//! sample, and the answers come back as IMC replies to the sender. Actuators become
//! `VehicleCommand`s (source `imc`) that autopilot-link's arbiter decides; LEDs,
//! GPIO, power channels, the LCD and the companion's own power become
//! `HardwareRequest`s the `hardware` service executes; buttons and remote actions
//! become `ButtonEvent`s and velocity setpoints. Everything refused is counted and
//! logged, never fatal, never a change of state.
//!
//! | module | role |
//! |---|---|
//! | [`config`] | TOML → [`Settings`] (mapping tables, identity, teleoperation) |
//! | [`engine`] | every decision, pure: datagrams and samples in, outputs out |
//! | [`actuators`], [`teleop`], [`hardware`], [`commands`], [`peers`] | the pure rules the engine applies |
//! | `gateway` | the one loop: socket, bus, tick → engine → send/publish |
//! | `ipc` | every bus call |
//! | [`metrics`], `drops` | counters; rate-limited logging of refused input |
//! | [`client`], [`describe`], [`cli`] | the peer side: a client for tests and the `skymesh-imc` CLI |
//! | [`service`] | runtime glue for `service_main` |
//!
//! Entry points: [`bind`] then [`run`].
#![forbid(unsafe_code)]

pub mod actuators;
pub mod cli;
pub mod client;
pub mod commands;
pub mod config;
pub mod describe;
mod drops;
pub mod engine;
mod gateway;
pub mod hardware;
mod ipc;
pub mod metrics;
pub mod peers;
pub mod service;
pub mod teleop;

use anyhow::Context as _;
use tokio::net::UdpSocket;

pub use config::{RawConfig, Settings};
pub use gateway::run;

/// Binds `settings.listen` (tests use port 0; [`run`] reads the bound port for its
/// Announce).
pub async fn bind(settings: &Settings) -> anyhow::Result<UdpSocket> {
    UdpSocket::bind(settings.listen)
        .await
        .with_context(|| format!("binding the IMC socket on udp {}", settings.listen))
}
