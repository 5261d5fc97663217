//! The 3DR Solo app ↔ ShotManager protocol: message types and a pure codec.
//!
//! No I/O and no runtime: the `solo-gateway` service owns the sockets (TCP 5507 for
//! the app connection, UDP 14558 for the follow stream) and uses [`TlvCodec`] with
//! `tokio_util::codec::Framed`, and translates decoded messages into the shot
//! engine's protocol-neutral requests and its events back (the engine never sees
//! this crate).
//!
//! Wire format (`../shared/specs/solo-app-shotmanager.md`, corrected by
//! `../shared/specs/FACTS.md`): little-endian TLV, `u32 type, u32 length, value`.
//! Decoding is two steps so a bad value never desynchronises the stream:
//!
//! | step | function | rejects |
//! |---|---|---|
//! | cut one frame | [`TlvCodec`] (`Decoder<Item = RawFrame>`) | declared length > [`MAX_VALUE_LEN`] ([`FrameError::TooLong`]) before buffering it |
//! | read the value | [`SoloMessage::decode`] | unknown type, wrong length, NaN/∞, out-of-range enumerations and coordinates ([`DecodeError`]) |
//! | one datagram | [`decode_datagram`] | short datagrams and trailing bytes ([`DatagramError`]) |
//!
//! Message families, one file each:
//!
//! | file | messages |
//! |---|---|
//! | `general.rs` | current shot, location, record position, button settings, pause, shot error, ShotManager error, cable cam waypoint, second phone, home location |
//! | `options.rs` | cable cam, follow (v1, v2), shot, pano, zipline, rewind options; pano state; zipline lock |
//! | `spline.rs` | multipoint cable cam: record, play, point, seek, playback status, path settings, durations, attach |
//! | `gopro.rs` | GoPro enable, set requests, record, V1/V2 state, request state, photo |
//! | `geofence.rs` | set data (JSON), ack, update polygon, clear, activated |
//! | `sitescan.rs` | inspect start / waypoint / gimbal / vehicle, scan start, survey start |
//! | `catalog.rs` | per type id: name, value length, direction, family |
//! | `frame.rs` | header, [`TlvCodec`], [`decode_datagram`] |
#![forbid(unsafe_code)]

mod catalog;
mod error;
mod frame;
mod general;
mod geofence;
mod gopro;
pub mod ids;
mod message;
mod options;
pub mod shots;
mod sitescan;
mod spline;
mod wire;

pub use catalog::{direction, expected_len, known_types, message_name, Direction, ValueLen};
pub use error::{DatagramError, DecodeError, FrameError};
pub use frame::{decode_datagram, RawFrame, TlvCodec};
pub use general::{ButtonSetting, Location};
pub use geofence::GeofenceData;
pub use gopro::GoProState;
pub use message::SoloMessage;
pub use spline::SplinePoint;

/// Bytes of the frame header: `u32 type` then `u32 length`, little-endian.
pub const HEADER_LEN: usize = 8;

/// The largest value [`TlvCodec::new`] accepts. A declared length above this closes
/// the connection (the reference ShotManager would wait forever for the bytes).
pub const MAX_VALUE_LEN: usize = 64 * 1024;

/// The largest speed (m/s, either sign) accepted in cruise-speed and velocity
/// fields. Solo tops out near 25 m/s; anything beyond this is a corrupt value.
pub const MAX_SPEED_MPS: f32 = 100.0;
