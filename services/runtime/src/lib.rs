//! What every skymesh service shares.
//!
//! A service is a library with a thin `main`: it implements [`ServiceConfig`] for its
//! raw TOML config and calls [`service_main`] with an async `run(settings, ctx)`.
//! The runtime then owns everything that must be identical in every process:
//!
//! - the command line (`--config`, `--check-config`, `--print-default-config`, `--name`),
//! - config loading (TOML → validated settings; exit 64 when bad),
//! - structured logs (`tracing`: journald under systemd, text, or JSON; [`logging`]),
//! - the iceoryx2 node, created from one explicitly loaded config file with the
//!   domain from `SKYMESH_DOMAIN` (all iceoryx2 calls live in [`ipc`]),
//! - typed publishers and subscribers that wake through events (no spinning),
//!   awaited in tokio,
//! - heartbeat and stats publishing for the supervisor, systemd notify/watchdog,
//! - SIGTERM/SIGINT → one [`CancellationToken`] → graceful shutdown.
#![deny(unsafe_code)]

pub mod addresses;
pub mod angle;
pub mod backend;
pub mod backoff;
pub mod clock;
pub mod config;
pub mod exit;
pub mod frames;
pub mod health;
pub mod ipc;
pub mod logging;
pub mod net;
pub mod rate;
pub mod realtime;
pub mod refusals;
mod service;
pub mod signals;
pub mod state_file;
pub mod stats;
pub mod systemd;
pub mod timer;
pub mod warn_limit;

pub use backoff::Backoff;
pub use config::{ConfigError, ServiceConfig};
pub use frames::{FrameError, FramePublisher, FrameSubscriber};
pub use ipc::{Bus, Domain, IpcError, Publisher, Subscriber};
pub use rate::TokenBucket;
pub use service::{service_main, CommonArgs, Context, ServiceSpec};
pub use stats::{Counter, CounterFamily, Gauge, Histogram, Stats};
pub use tokio_util::sync::CancellationToken;
pub use warn_limit::{WarnLimiter, WARN_EVERY};
