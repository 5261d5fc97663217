//! What to do with one frame from the app (pure).
//!
//! A frame goes on the bus only if its value decodes cleanly as its type, the type
//! is one the app may send, and the value fits in an `AppMessage`. Everything else is
//! dropped with a [`Malformed`] kind, except a valid value too long for the bus
//! (GEOFENCE_SET_DATA JSON), which the gateway answers itself.

use bytes::{Bytes, BytesMut};
use skymesh_ipc_types::APP_VALUE_CAPACITY;
use solo_proto::{ids, Direction, RawFrame, SoloMessage};

use crate::metrics::Malformed;

/// The decision about one frame from the app.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// Publish the frame's value as received.
    Forward(SoloMessage),
    /// Drop it: count `kind`, log `reason`.
    Drop { kind: Malformed, reason: String },
    /// Valid, but longer than the bus carries: count `too_large_for_bus` and write
    /// `replies` to the app instead (each one whole TLV frame).
    Answer {
        message: SoloMessage,
        reason: String,
        replies: Vec<SoloMessage>,
    },
}

/// Checks a frame that arrived on the app's TCP connection.
pub fn check(frame: &RawFrame) -> Verdict {
    let message = match SoloMessage::decode(frame.msg_type, &frame.value) {
        Ok(m) => m,
        Err(e) => {
            return Verdict::Drop {
                kind: Malformed::from_decode(&e),
                reason: e.to_string(),
            }
        }
    };
    if solo_proto::direction(frame.msg_type) == Some(Direction::VehicleToApp) {
        return Verdict::Drop {
            kind: Malformed::WrongDirection,
            reason: format!(
                "{} (type {}) is sent by the vehicle, not the app",
                message.name(),
                frame.msg_type
            ),
        };
    }
    if frame.value.len() > APP_VALUE_CAPACITY {
        return too_large(message, frame.value.len());
    }
    Verdict::Forward(message)
}

fn too_large(message: SoloMessage, len: usize) -> Verdict {
    let reason = format!(
        "{} (type {}) value of {len} bytes exceeds the bus capacity of {APP_VALUE_CAPACITY}",
        message.name(),
        message.msg_type()
    );
    let replies = if message.msg_type() == ids::GEOFENCE_SET_DATA {
        vec![
            SoloMessage::GeofenceSetAck {
                count: 0,
                valid: false,
            },
            SoloMessage::ShotManagerError(format!(
                "skymesh: geofence polygon data (GEOFENCE_SET_DATA, {len} bytes) is not implemented yet: \
                 the shot engine's geofence is a later milestone. No geofence was set."
            )),
        ]
    } else {
        vec![SoloMessage::ShotManagerError(format!(
            "skymesh: {} message of {len} bytes is larger than skymesh carries ({APP_VALUE_CAPACITY}); ignored.",
            message.name()
        ))]
    };
    Verdict::Answer {
        message,
        reason,
        replies,
    }
}

/// `header + value` of a message: one TLV frame.
pub fn frame_bytes(msg_type: u32, value: &[u8]) -> Bytes {
    let mut b = BytesMut::with_capacity(solo_proto::HEADER_LEN + value.len());
    b.extend_from_slice(&msg_type.to_le_bytes());
    b.extend_from_slice(&(value.len() as u32).to_le_bytes());
    b.extend_from_slice(value);
    b.freeze()
}

#[cfg(test)]
mod tests {
    use super::*;
    use solo_proto::GeofenceData;

    fn raw(msg_type: u32, value: &[u8]) -> RawFrame {
        RawFrame {
            msg_type,
            value: Bytes::copy_from_slice(value),
        }
    }

    fn value_of(m: &SoloMessage) -> Vec<u8> {
        let mut b = BytesMut::new();
        m.encode_value(&mut b);
        b.to_vec()
    }

    fn kind(v: Verdict) -> Malformed {
        match v {
            Verdict::Drop { kind, .. } => kind,
            other => panic!("expected a drop, got {other:?}"),
        }
    }

    #[test]
    fn valid_app_messages_are_forwarded() {
        for m in [
            SoloMessage::SetCurrentShot(1),
            SoloMessage::Pause,
            SoloMessage::ShotOptions { cruise_speed: 3.0 },
            SoloMessage::GoProRecord(2),
        ] {
            assert_eq!(
                check(&raw(m.msg_type(), &value_of(&m))),
                Verdict::Forward(m)
            );
        }
    }

    #[test]
    fn bad_frames_are_dropped_by_kind() {
        assert_eq!(
            kind(check(&raw(ids::SET_CURRENT_SHOT, &[1, 0, 0]))),
            Malformed::WrongLength
        );
        assert_eq!(kind(check(&raw(4242, &[]))), Malformed::UnknownType);
        let get = SoloMessage::GetCurrentShot(1);
        assert_eq!(
            kind(check(&raw(get.msg_type(), &value_of(&get)))),
            Malformed::WrongDirection
        );
        let mut nan = value_of(&SoloMessage::Location(solo_proto::Location {
            lat_deg: 1.0,
            lon_deg: 2.0,
            alt_m: 3.0,
        }));
        nan[..8].copy_from_slice(&f64::NAN.to_le_bytes());
        assert_eq!(
            kind(check(&raw(ids::LOCATION, &nan))),
            Malformed::InvalidValue
        );
    }

    #[test]
    fn a_long_geofence_is_answered_not_forwarded() {
        let square = vec![
            [37.0, -122.0],
            [37.001, -122.0],
            [37.001, -122.001],
            [37.0, -122.001],
        ];
        let fence = SoloMessage::GeofenceSetData(GeofenceData {
            coord: vec![square.clone(), square.clone()],
            sub_coord: vec![square.clone(), square],
            kinds: vec![0, 1],
        });
        let value = value_of(&fence);
        assert!(value.len() > APP_VALUE_CAPACITY, "{}", value.len());
        match check(&raw(ids::GEOFENCE_SET_DATA, &value)) {
            Verdict::Answer { replies, .. } => {
                assert_eq!(
                    replies[0],
                    SoloMessage::GeofenceSetAck {
                        count: 0,
                        valid: false
                    }
                );
                assert!(
                    matches!(&replies[1], SoloMessage::ShotManagerError(t) if t.contains("not implemented")),
                    "{replies:?}"
                );
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn frames_are_header_then_value() {
        assert_eq!(
            frame_bytes(1002, &[]).as_ref(),
            &[0xea, 0x03, 0, 0, 0, 0, 0, 0]
        );
        assert_eq!(
            frame_bytes(1, &[1, 0, 0, 0]),
            SoloMessage::SetCurrentShot(1).to_bytes()
        );
    }
}
