//! General messages: current shot, locations, record position, button settings,
//! pause, shot errors, ShotManager errors, cable cam waypoints, second phone.

use bytes::{BufMut, BytesMut};

use crate::error::DecodeError;
use crate::ids;
use crate::message::SoloMessage;
use crate::shots;
use crate::wire::Reader;

/// A position: SOLO_MESSAGE_LOCATION (app → ShotManager: ROI, selfie points, follow
/// stream; ShotManager → app: the ROI it uses) and SOLO_HOME_LOCATION. 20 bytes:
/// `f64 lat, f64 lon, f32 alt`. Altitude is metres relative to home.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Location {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_m: f32,
}

/// An Artoo button mapping (GET/SET_BUTTON_SETTING), 16 bytes of `i32`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ButtonSetting {
    /// 0 power, 1 fly, 2 RTL, 3 loiter, 4 A, 5 B, 6 preset 1, 7 preset 2, 8 camera.
    pub button: i32,
    /// 0 press, 1 release, 2 click-release, 3 hold, 4 long hold, 5 double click.
    pub event: i32,
    /// Shot index ([`crate::shots`]) or −1.
    pub shot: i32,
    /// ArduCopter mode number or −1. The spec says one of shot/mode should be −1;
    /// that is not enforced (a GET request carries −1 in both).
    pub mode: i32,
}

pub(crate) fn put_location(l: &Location, dst: &mut BytesMut) {
    dst.put_f64_le(l.lat_deg);
    dst.put_f64_le(l.lon_deg);
    dst.put_f32_le(l.alt_m);
}

pub(crate) fn read_location(r: &mut Reader<'_>) -> Result<Location, DecodeError> {
    Ok(Location {
        lat_deg: r.lat("latitude")?,
        lon_deg: r.lon("longitude")?,
        alt_m: r.f32("altitude")?,
    })
}

fn put_button(b: &ButtonSetting, dst: &mut BytesMut) {
    dst.put_i32_le(b.button);
    dst.put_i32_le(b.event);
    dst.put_i32_le(b.shot);
    dst.put_i32_le(b.mode);
}

fn read_button(r: &mut Reader<'_>) -> Result<ButtonSetting, DecodeError> {
    Ok(ButtonSetting {
        button: r.i32_in("button", 0, 8)?,
        event: r.i32_in("event", 0, 5)?,
        shot: r.i32_in("shot", shots::MIN, shots::MAX)?,
        mode: r.i32_in("mode", -1, i32::MAX)?,
    })
}

pub(crate) fn encode(msg: &SoloMessage, dst: &mut BytesMut) {
    use SoloMessage as M;
    match msg {
        M::GetCurrentShot(shot) | M::SetCurrentShot(shot) => dst.put_i32_le(*shot),
        M::Location(l) | M::HomeLocation(l) => put_location(l, dst),
        M::GetButtonSetting(b) | M::SetButtonSetting(b) => put_button(b, dst),
        M::ShotError(e) => dst.put_u32_le(*e),
        M::ShotManagerError(text) => dst.put_slice(text.as_bytes()),
        M::CableCamWaypoint {
            lat_deg,
            lon_deg,
            alt_m,
            yaw_deg,
            pitch_deg,
        } => {
            dst.put_f64_le(*lat_deg);
            dst.put_f64_le(*lon_deg);
            dst.put_f32_le(*alt_m);
            dst.put_f32_le(*yaw_deg);
            dst.put_f32_le(*pitch_deg);
        }
        M::RecordPosition | M::Pause | M::SecondPhoneNotification => {}
        other => debug_assert!(false, "{} is not a general message", other.name()),
    }
}

pub(crate) fn decode(r: &mut Reader<'_>) -> Result<SoloMessage, DecodeError> {
    Ok(match r.msg_type() {
        ids::GET_CURRENT_SHOT => {
            SoloMessage::GetCurrentShot(r.i32_in("shot", shots::MIN, shots::MAX)?)
        }
        ids::SET_CURRENT_SHOT => {
            SoloMessage::SetCurrentShot(r.i32_in("shot", shots::MIN, shots::MAX)?)
        }
        ids::LOCATION => SoloMessage::Location(read_location(r)?),
        ids::HOME_LOCATION => SoloMessage::HomeLocation(read_location(r)?),
        ids::RECORD_POSITION => SoloMessage::RecordPosition,
        ids::GET_BUTTON_SETTING => SoloMessage::GetButtonSetting(read_button(r)?),
        ids::SET_BUTTON_SETTING => SoloMessage::SetButtonSetting(read_button(r)?),
        // Empty: see the catalog (the spec's length 8 lists no field).
        ids::PAUSE => SoloMessage::Pause,
        ids::SHOT_ERROR => SoloMessage::ShotError(r.u32_in("error_type", 0, 2)?),
        ids::SHOTMANAGER_ERROR => {
            SoloMessage::ShotManagerError(String::from_utf8_lossy(r.take_rest()).into_owned())
        }
        ids::CABLE_CAM_WAYPOINT => SoloMessage::CableCamWaypoint {
            lat_deg: r.lat("latitude")?,
            lon_deg: r.lon("longitude")?,
            alt_m: r.f32("altitude")?,
            yaw_deg: r.f32("yaw")?,
            pitch_deg: r.f32("pitch")?,
        },
        ids::SECOND_PHONE_NOTIFICATION => SoloMessage::SecondPhoneNotification,
        other => return Err(DecodeError::UnknownType(other)),
    })
}
