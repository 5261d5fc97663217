//! skymesh dji-gateway: the device side of the DJI Cloud API live flight controls
//! (`../shared/specs/dji-cloud-live-flight-controls.md` with `specs/FACTS.md`). A
//! cloud written for the DJI Cloud API talks MQTT to "the dock" `gateway_sn`; this
//! gateway answers as that dock and flies a MAVLink aircraft through skymesh's
//! arbiter (source `dji_drc`): directly for authority, payload and DRC sticks, and
//! through the shot engine's task runner for takeoff_to_point, fly_to_point, POI
//! and the panorama sweep (the flight logic is the engine's; the gateway
//! translates).
//!
//! | module | role |
//! |---|---|
//! | [`config`] | TOML → [`Settings`] |
//! | [`mqtt`], [`tls`] | the cloud broker connection: credentials, TLS (rustls/ring), reconnect with the runtime's jittered backoff |
//! | [`outbox`], [`ratelimit`] | outbound queue kept across reconnects, need_reply re-sends; inbound rate limit (pure) |
//! | [`inbound`] | the checks of one inbound message, in order (pure) |
//! | `gateway` | the one loop: MQTT in/out, replies and events, authority keep-alive |
//! | [`dispatch`] | the checks every service shares (gateway, payload_index, authority) and each method's execution |
//! | [`tasks`] | takeoff_to_point, fly_to_point, POI, panorama ↔ the shot engine's task runner (`TaskRequest` / `TaskEvent`) |
//! | [`progress`] | DJI ellipsoid heights ↔ above home, the planned path points |
//! | [`payload`] | payload methods → camera/gimbal commands (pure) |
//! | [`pano`] | panorama capture (camera_mode_switch 3 + camera_photo_take): the runner's Pano events → camera_photo_take_progress |
//! | [`shared`] | what tasks share: settings, vehicle link, reply/event emitter, result-code mapping |
//! | [`link`] | the bus: vehicle samples and commands with their acks |
//! | [`drc`] | the DRC link (drc/down, drc/up on the broker `drc_mode_enter` names) |
//! | [`metrics`] | `skymesh_dji_*` series |
//! | [`cloud`] | a test "cloud" client |
//!
//! Entry point: [`run`].
#![forbid(unsafe_code)]

pub mod cloud;
pub mod config;
pub mod dispatch;
pub mod drc;
mod gateway;
pub mod inbound;
pub mod link;
pub mod metrics;
pub mod mqtt;
pub mod outbox;
pub mod pano;
pub mod payload;
pub mod progress;
pub mod ratelimit;
pub mod service;
pub mod shared;
pub mod tasks;
pub mod tls;

pub use config::{RawConfig, Settings};
pub use gateway::{now_ms, run, uuid};
