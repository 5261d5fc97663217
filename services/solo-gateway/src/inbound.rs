//! What to do with one frame from the app (pure).
//!
//! A frame goes on the bus only if its value decodes cleanly as its type and the
//! type is one the app may send; it goes as the engine's `ShotRequest`
//! ([`crate::translate`]), each of which fits a sample. Everything else is dropped
//! with a [`Malformed`] kind.
//!
//! GEOFENCE_SET_DATA (JSON, up to 64 KiB) is no `ShotRequest`: its polygons
//! are translated into one `AppGeofence` sample, whatever its length. What that
//! sample cannot carry (more than 8 polygons, or more than 32 vertices in a polygon
//! or sub-polygon) is answered here with GEOFENCE_SET_ACK {0, false} and a
//! SHOTMANAGER_ERROR naming the limit, and counted `too_large_for_bus`. Whether the
//! polygons make a usable fence is the shot engine's decision (gateways translate,
//! engines decide): it answers everything that is forwarded.
//!
//! A geofence request that does not decode (GEOFENCE_SET_DATA: bad JSON, `coord`,
//! `subCoord` and `type` of different lengths, a bad coordinate or type;
//! GEOFENCE_UPDATE_POLY: wrong length, bad action or coordinate) is not dropped
//! silently like other malformed frames: the app waits for a GEOFENCE_SET_ACK, so
//! the gateway answers GEOFENCE_SET_ACK {0, false} and a SHOTMANAGER_ERROR saying
//! why, and counts it under its malformed kind. Nothing reaches the engine, whose
//! fence is unchanged. GEOFENCE_CLEAR of the wrong length, and any geofence request
//! beyond the client's rate ([`rate_limited`]), get the same answer.
//!
//! A SPLINE_POINT whose magnitudes are refused ([`magnitudes`]) is answered with the
//! app's own point and status −4 ([`SPLINE_POINT_FAILED`]): the app waits for one
//! SPLINE_POINT per SPLINE_POINT, and the engine answers a refused keypoint the same
//! way.

use bytes::{Bytes, BytesMut};
use skymesh_ipc_types::AppGeofence;
use solo_proto::{Direction, GeofenceData, RawFrame, SoloMessage};

use crate::metrics::Malformed;

/// The decision about one frame from the app.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// Publish the message as the engine's request.
    Forward(SoloMessage),
    /// GEOFENCE_SET_DATA: publish its polygons (the session is filled in by the
    /// publisher).
    Geofence(Box<AppGeofence>),
    /// Drop it: count `kind`, log `reason`.
    Drop { kind: Malformed, reason: String },
    /// Not forwarded but answered: count `kind` (`too_large_for_bus`: valid but
    /// longer than the bus carries; a malformed kind: a geofence request that does
    /// not decode), log `reason` and write `replies` to the app (each one whole TLV
    /// frame).
    Answer {
        msg_type: u32,
        kind: Malformed,
        reason: String,
        replies: Vec<SoloMessage>,
    },
}

/// Checks a frame that arrived on the app's TCP connection.
pub fn check(frame: &RawFrame) -> Verdict {
    let message = match SoloMessage::decode(frame.msg_type, &frame.value) {
        Ok(m) => m,
        Err(e) if is_geofence_request(frame.msg_type) => return bad_geofence(frame.msg_type, &e),
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
    if let Err(reason) = magnitudes(&message) {
        if let SoloMessage::SplinePoint(p) = &message {
            // The app waits for one SPLINE_POINT per SPLINE_POINT: its own point
            // back with a failure status, as the engine answers a refused keypoint.
            let failed = SoloMessage::SplinePoint(solo_proto::SplinePoint {
                status: SPLINE_POINT_FAILED,
                ..*p
            });
            return Verdict::Answer {
                msg_type: frame.msg_type,
                kind: Malformed::InvalidValue,
                reason,
                replies: vec![failed],
            };
        }
        return Verdict::Drop {
            kind: Malformed::InvalidValue,
            reason,
        };
    }
    if let SoloMessage::GeofenceSetData(data) = &message {
        return geofence(data, &message);
    }
    Verdict::Forward(message)
}

/// SOLO_SPLINE_POINT status "anything else" (the spec's -4), the answer to a
/// keypoint the gateway refuses.
pub const SPLINE_POINT_FAILED: i16 = -4;

/// The decision about a frame beyond the client's rate: dropped and counted, but a
/// geofence request is still answered GEOFENCE_SET_ACK {0, false} (the app waits
/// for it; the fence is unchanged).
pub fn rate_limited(frame: &RawFrame, reason: String) -> Verdict {
    if !is_geofence_request(frame.msg_type) {
        return Verdict::Drop {
            kind: Malformed::RateLimited,
            reason,
        };
    }
    Verdict::Answer {
        msg_type: frame.msg_type,
        kind: Malformed::RateLimited,
        replies: vec![
            SoloMessage::GeofenceSetAck {
                count: 0,
                valid: false,
            },
            SoloMessage::ShotManagerError(format!(
                "skymesh: geofence not set: {reason}. The vehicle's geofence is unchanged."
            )),
        ],
        reason,
    }
}

/// Largest altitude or distance the gateway forwards, metres (either sign).
pub const MAX_DISTANCE_M: f32 = 50_000.0;
/// Largest angle or angular rate, degrees (either sign: ten turns).
pub const MAX_ANGLE_DEG: f32 = 3_600.0;
/// Largest duration, seconds (a day).
pub const MAX_TIME_S: f32 = 86_400.0;
/// Largest spline parameter (normalised 0..1; the reference clamps, so only an
/// absurd value is refused here).
pub const MAX_U: f32 = 1_000.0;

/// `solo-proto` refuses NaN/±∞ in every float and range-checks latitudes,
/// longitudes and speeds; the other floats (altitudes, angles, durations, spline
/// positions) it only requires finite, because the reference ShotManager clamps
/// them. An absurd magnitude is still no value to put on the bus: refused here.
pub fn magnitudes(m: &SoloMessage) -> Result<(), String> {
    use SoloMessage as M;
    let check = |name: &str, v: f32, max: f32| {
        if v.is_finite() && v.abs() <= max {
            Ok(())
        } else {
            Err(format!("{}: {name} {v} is beyond ±{max}", m.name()))
        }
    };
    match m {
        M::Location(l) | M::HomeLocation(l) => check("altitude", l.alt_m, MAX_DISTANCE_M),
        M::PanoOptions {
            deg_second_yaw,
            lens_fov,
            ..
        } => {
            check("deg_second_yaw", *deg_second_yaw, MAX_ANGLE_DEG)?;
            check("lens_fov", *lens_fov, MAX_ANGLE_DEG)
        }
        M::RewindOptions {
            rewind_distance, ..
        } => check("rewind_distance", *rewind_distance, MAX_DISTANCE_M),
        M::SplinePoint(p) => {
            check("abs_alt_ref", p.abs_alt_ref_m, MAX_DISTANCE_M)?;
            check("altitude", p.alt_m, MAX_DISTANCE_M)?;
            check("pitch", p.pitch_deg, MAX_ANGLE_DEG)?;
            check("yaw", p.yaw_deg, MAX_ANGLE_DEG)?;
            check("u_position", p.u_position, MAX_U)
        }
        M::SplineSeek { u_position, .. } | M::SplinePlaybackStatus { u_position, .. } => {
            check("u_position", *u_position, MAX_U)
        }
        M::SplinePathSettings { desired_time_s, .. } => {
            check("desired_time", *desired_time_s, MAX_TIME_S)
        }
        M::SplineDurations {
            min_time_s,
            max_time_s,
        } => {
            check("min_time", *min_time_s, MAX_TIME_S)?;
            check("max_time", *max_time_s, MAX_TIME_S)
        }
        M::CableCamWaypoint {
            alt_m,
            yaw_deg,
            pitch_deg,
            ..
        } => {
            check("altitude", *alt_m, MAX_DISTANCE_M)?;
            check("yaw", *yaw_deg, MAX_ANGLE_DEG)?;
            check("pitch", *pitch_deg, MAX_ANGLE_DEG)
        }
        M::GoProPhoto { alt_m, .. } | M::InspectSetWaypoint { alt_m, .. } => {
            check("altitude", *alt_m, MAX_DISTANCE_M)
        }
        M::InspectStart { takeoff_alt_m } => check("takeoff_alt", *takeoff_alt_m, MAX_DISTANCE_M),
        M::InspectMoveGimbal {
            pitch_deg,
            roll_deg,
            yaw_deg,
        } => {
            check("pitch", *pitch_deg, MAX_ANGLE_DEG)?;
            check("roll", *roll_deg, MAX_ANGLE_DEG)?;
            check("yaw", *yaw_deg, MAX_ANGLE_DEG)
        }
        _ => Ok(()),
    }
}

/// The app's requests the shot engine answers (the setting, the GoPro state, the
/// point with its status, the current shot, GEOFENCE_SET_ACK). Every other message
/// the app sends has no reply in the protocol.
pub fn expects_reply(msg_type: u32) -> bool {
    use solo_proto::ids;
    is_geofence_request(msg_type)
        || matches!(
            msg_type,
            ids::GET_BUTTON_SETTING
                | ids::GOPRO_REQUEST_STATE
                | ids::SPLINE_POINT
                | ids::SET_CURRENT_SHOT
        )
}

/// The gateway's answer to a request the shot engine answers ([`expects_reply`]),
/// when no shot engine read the bus within `waited`: the protocol's error instead
/// of silence. A geofence request gets GEOFENCE_SET_ACK {0, false}, a SPLINE_POINT
/// the app's point with status −4 (`message` is the decoded request), every one a
/// SHOTMANAGER_ERROR saying why. `None` for a message without reply: it is
/// forwarded as usual.
pub fn backend_missing(
    msg_type: u32,
    message: Option<&SoloMessage>,
    waited: std::time::Duration,
) -> Option<Verdict> {
    if !expects_reply(msg_type) {
        return None;
    }
    let name = solo_proto::message_name(msg_type).unwrap_or("request");
    let reason = format!(
        "{name} (type {msg_type}): no shot engine reads the bus after waiting {} ms; answered by the gateway",
        waited.as_millis()
    );
    let mut replies = Vec::with_capacity(2);
    if is_geofence_request(msg_type) {
        replies.push(SoloMessage::GeofenceSetAck {
            count: 0,
            valid: false,
        });
    }
    if let Some(SoloMessage::SplinePoint(p)) = message {
        replies.push(SoloMessage::SplinePoint(solo_proto::SplinePoint {
            status: SPLINE_POINT_FAILED,
            ..*p
        }));
    }
    replies.push(SoloMessage::ShotManagerError(format!(
        "skymesh: {name} not served: the shot engine is not running. Nothing was changed; retry when it is back."
    )));
    Some(Verdict::Answer {
        msg_type,
        kind: Malformed::BackendMissing,
        reason,
        replies,
    })
}

/// The app's geofence requests, each answered with a GEOFENCE_SET_ACK (the spec:
/// after GEOFENCE_SET_DATA, GEOFENCE_UPDATE_POLY or GEOFENCE_CLEAR).
fn is_geofence_request(msg_type: u32) -> bool {
    matches!(
        msg_type,
        solo_proto::ids::GEOFENCE_SET_DATA
            | solo_proto::ids::GEOFENCE_UPDATE_POLY
            | solo_proto::ids::GEOFENCE_CLEAR
    )
}

/// A geofence request that does not decode: answered negatively, never dropped.
fn bad_geofence(msg_type: u32, e: &solo_proto::DecodeError) -> Verdict {
    Verdict::Answer {
        msg_type,
        kind: Malformed::from_decode(e),
        reason: e.to_string(),
        replies: vec![
            SoloMessage::GeofenceSetAck {
                count: 0,
                valid: false,
            },
            SoloMessage::ShotManagerError(format!(
                "skymesh: geofence not set: {e}. The vehicle's geofence is unchanged."
            )),
        ],
    }
}

/// GEOFENCE_SET_DATA → one `AppGeofence`, or the answer when it cannot be carried.
fn geofence(data: &GeofenceData, message: &SoloMessage) -> Verdict {
    let polygons = data
        .kinds
        .iter()
        .zip(data.coord.iter().zip(&data.sub_coord))
        .map(|(kind, (coord, sub))| (*kind, coord.as_slice(), sub.as_slice()));
    match AppGeofence::new(0, polygons) {
        Ok(fence) => Verdict::Geofence(Box::new(fence)),
        Err(e) => Verdict::Answer {
            msg_type: message.msg_type(),
            kind: Malformed::TooLargeForBus,
            reason: format!("geofence_set_data: {e}"),
            replies: vec![
                SoloMessage::GeofenceSetAck {
                    count: 0,
                    valid: false,
                },
                SoloMessage::ShotManagerError(format!(
                    "skymesh: geofence not set: {e}. No geofence was set."
                )),
            ],
        },
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
    use solo_proto::ids;

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
    fn without_an_engine_requests_get_the_protocol_error_and_the_rest_is_forwarded() {
        let waited = std::time::Duration::from_millis(2000);
        let error = |r: &SoloMessage| matches!(r, SoloMessage::ShotManagerError(t) if t.contains("shot engine is not running"));
        for t in [
            ids::GEOFENCE_SET_DATA,
            ids::GEOFENCE_UPDATE_POLY,
            ids::GEOFENCE_CLEAR,
        ] {
            let Some(Verdict::Answer { kind, replies, .. }) = backend_missing(t, None, waited)
            else {
                panic!("type {t} must be answered");
            };
            assert_eq!(kind, Malformed::BackendMissing);
            assert_eq!(
                replies[0],
                SoloMessage::GeofenceSetAck {
                    count: 0,
                    valid: false
                }
            );
            assert!(error(&replies[1]), "{replies:?}");
        }
        let point = solo_proto::SplinePoint {
            version: 0,
            abs_alt_ref_m: 10.0,
            index: 3,
            lat_deg: 37.0,
            lon_deg: -122.0,
            alt_m: 20.0,
            pitch_deg: -10.0,
            yaw_deg: 90.0,
            u_position: 0.0,
            status: 0,
        };
        let m = SoloMessage::SplinePoint(point);
        let Some(Verdict::Answer { replies, .. }) =
            backend_missing(ids::SPLINE_POINT, Some(&m), waited)
        else {
            panic!("SPLINE_POINT must be answered");
        };
        assert_eq!(
            replies[0],
            SoloMessage::SplinePoint(solo_proto::SplinePoint {
                status: SPLINE_POINT_FAILED,
                ..point
            })
        );
        assert!(error(&replies[1]));
        for t in [
            ids::GET_BUTTON_SETTING,
            ids::GOPRO_REQUEST_STATE,
            ids::SET_CURRENT_SHOT,
        ] {
            let Some(Verdict::Answer { replies, .. }) = backend_missing(t, None, waited) else {
                panic!("type {t} must be answered");
            };
            assert_eq!(replies.len(), 1);
            assert!(error(&replies[0]));
        }
        // No reply in the protocol: no invented one, forwarded as always.
        for t in [
            ids::LOCATION,
            ids::SET_BUTTON_SETTING,
            ids::PAUSE,
            ids::GOPRO_RECORD,
        ] {
            assert_eq!(backend_missing(t, None, waited), None, "type {t}");
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

    fn square(n: usize) -> Vec<[f64; 2]> {
        (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                [37.0 + 0.001 * a.sin(), -122.0 + 0.001 * a.cos()]
            })
            .collect()
    }

    fn fence_frame(coord: Vec<Vec<[f64; 2]>>, kinds: Vec<u8>) -> RawFrame {
        let fence = SoloMessage::GeofenceSetData(GeofenceData {
            sub_coord: coord.clone(),
            coord,
            kinds,
        });
        raw(ids::GEOFENCE_SET_DATA, &value_of(&fence))
    }

    #[test]
    fn a_geofence_of_any_length_is_translated_for_the_engine() {
        // Longer than a request sample, eight polygons of 32 vertices: carried whole.
        let frame = fence_frame(vec![square(32); 8], vec![0, 1, 1, 1, 1, 1, 1, 1]);
        assert!(
            frame.value.len() > skymesh_ipc_types::SHOT_BODY_CAPACITY,
            "{}",
            frame.value.len()
        );
        let Verdict::Geofence(g) = check(&frame) else {
            panic!("not translated");
        };
        assert_eq!(g.polygons().len(), 8);
        assert_eq!(g.polygons()[0].kind, 0);
        assert_eq!(g.polygons()[7].kind, 1);
        assert_eq!(g.polygons()[3].vertices(), square(32).as_slice());
        assert_eq!(g.polygons()[3].sub_vertices(), square(32).as_slice());
        // Short, and geometrically useless (2 vertices): still the engine's to judge.
        let Verdict::Geofence(g) = check(&fence_frame(vec![square(2)], vec![0])) else {
            panic!("not translated");
        };
        assert_eq!(g.polygons()[0].vertices().len(), 2);
    }

    #[test]
    fn a_geofence_the_bus_cannot_carry_is_answered_not_forwarded() {
        for (frame, limit) in [
            (fence_frame(vec![square(4); 9], vec![1; 9]), "9 polygons"),
            (
                fence_frame(vec![square(4), square(33)], vec![0, 1]),
                "33 vertices",
            ),
        ] {
            match check(&frame) {
                Verdict::Answer { replies, .. } => {
                    assert_eq!(
                        replies[0],
                        SoloMessage::GeofenceSetAck {
                            count: 0,
                            valid: false
                        }
                    );
                    assert!(
                        matches!(&replies[1], SoloMessage::ShotManagerError(t) if t.contains(limit)),
                        "{replies:?}"
                    );
                }
                other => panic!("{other:?}"),
            }
        }
    }

    #[test]
    fn a_malformed_geofence_request_is_answered_not_dropped() {
        let fence_json = |json: &str| raw(ids::GEOFENCE_SET_DATA, json.as_bytes());
        let a = [37.0, -122.0];
        let b = [37.001, -122.0];
        let c = [37.0, -122.001];
        let tri = format!("[{a:?},{b:?},{c:?}]");
        let frames = [
            // coord and subCoord of different lengths (issue 43 item 5).
            (
                fence_json(&format!(
                    r#"{{"coord":[{tri},{tri}],"subCoord":[{tri}],"type":[0,1]}}"#
                )),
                Malformed::InvalidValue,
                "different sizes",
            ),
            (fence_json("{\"coord\":"), Malformed::InvalidValue, "JSON"),
            (
                fence_json(&format!(
                    r#"{{"coord":[{tri}],"subCoord":[{tri}],"type":[7]}}"#
                )),
                Malformed::InvalidValue,
                "type[0]",
            ),
            (
                raw(ids::GEOFENCE_UPDATE_POLY, &[0, 0, 0]),
                Malformed::WrongLength,
                "bytes",
            ),
        ];
        for (frame, want_kind, why) in frames {
            match check(&frame) {
                Verdict::Answer {
                    msg_type,
                    kind,
                    reason,
                    replies,
                } => {
                    assert_eq!(msg_type, frame.msg_type);
                    assert_eq!(kind, want_kind, "{reason}");
                    assert!(reason.contains(why), "{reason}");
                    assert_eq!(
                        replies[0],
                        SoloMessage::GeofenceSetAck {
                            count: 0,
                            valid: false
                        }
                    );
                    assert!(
                        matches!(&replies[1], SoloMessage::ShotManagerError(t) if t.contains(why)),
                        "{replies:?}"
                    );
                }
                other => panic!("{why}: {other:?}"),
            }
        }
        // Other malformed frames are still dropped.
        assert_eq!(
            kind(check(&raw(ids::SET_CURRENT_SHOT, &[1, 0, 0]))),
            Malformed::WrongLength
        );
    }

    #[test]
    fn a_geofence_clear_of_the_wrong_length_is_answered() {
        match check(&raw(ids::GEOFENCE_CLEAR, &[1])) {
            Verdict::Answer { kind, replies, .. } => {
                assert_eq!(kind, Malformed::WrongLength);
                assert_eq!(
                    replies[0],
                    SoloMessage::GeofenceSetAck {
                        count: 0,
                        valid: false
                    }
                );
            }
            other => panic!("{other:?}"),
        }
        let clear = SoloMessage::GeofenceClear;
        assert_eq!(
            check(&raw(clear.msg_type(), &value_of(&clear))),
            Verdict::Forward(clear)
        );
    }

    #[test]
    fn a_rate_limited_geofence_request_is_still_answered() {
        for t in [
            ids::GEOFENCE_SET_DATA,
            ids::GEOFENCE_UPDATE_POLY,
            ids::GEOFENCE_CLEAR,
        ] {
            match rate_limited(&raw(t, &[]), "over the rate".into()) {
                Verdict::Answer {
                    msg_type,
                    kind,
                    replies,
                    ..
                } => {
                    assert_eq!((msg_type, kind), (t, Malformed::RateLimited));
                    assert_eq!(
                        replies[0],
                        SoloMessage::GeofenceSetAck {
                            count: 0,
                            valid: false
                        }
                    );
                }
                other => panic!("{t}: {other:?}"),
            }
        }
        let pause = SoloMessage::Pause;
        assert_eq!(
            kind(rate_limited(&raw(pause.msg_type(), &[]), "x".into())),
            Malformed::RateLimited
        );
    }

    #[test]
    fn a_refused_spline_point_is_answered_with_a_failure_status() {
        let p = solo_proto::SplinePoint {
            version: 0,
            abs_alt_ref_m: 10.0,
            index: 3,
            lat_deg: 37.0,
            lon_deg: -122.0,
            alt_m: 1.0e6,
            pitch_deg: 0.0,
            yaw_deg: 0.0,
            u_position: 0.0,
            status: 0,
        };
        let m = SoloMessage::SplinePoint(p);
        match check(&raw(m.msg_type(), &value_of(&m))) {
            Verdict::Answer { kind, replies, .. } => {
                assert_eq!(kind, Malformed::InvalidValue);
                assert_eq!(
                    replies,
                    vec![SoloMessage::SplinePoint(solo_proto::SplinePoint {
                        status: SPLINE_POINT_FAILED,
                        ..p
                    })]
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
