//! GoPro messages: enable, set requests (legacy and extended), record, state (V1 and
//! V2 share one 36-byte layout), request state, and the photo log (OpenSolo).

use bytes::{BufMut, BytesMut};

use crate::error::DecodeError;
use crate::ids;
use crate::message::SoloMessage;
use crate::wire::Reader;

/// GOPRO_V1_STATE / GOPRO_V2_STATE value: 26 × `u8` then 5 × `u16` (36 bytes).
/// Values are what the camera reports and depend on its model, so they are carried
/// verbatim and not range-checked. V1 only fills the fields through `capture_mode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GoProState {
    pub version: u8,
    pub model: u8,
    /// 0 no GoPro, 1 incompatible, 2 connected, 3 error.
    pub status: u8,
    /// 0 not recording, 1 recording.
    pub recording: u8,
    /// 0 video, 1 photo, 2 burst, 3 time-lapse, 4 multishot.
    pub capture_mode: u8,
    /// 0 NTSC, 1 PAL.
    pub ntsc_pal: u8,
    pub video_resolution: u8,
    pub video_fps: u8,
    pub video_fov: u8,
    pub video_low_light: u8,
    pub photo_resolution: u8,
    pub photo_burst_rate: u8,
    pub video_protune: u8,
    pub video_white_balance: u8,
    pub video_color: u8,
    pub video_gain: u8,
    pub video_sharpness: u8,
    pub video_exposure: u8,
    pub gimbal_enabled: u8,
    /// Reserved.
    pub extra_u8: [u8; 7],
    /// Reserved.
    pub extra_u16: [u16; 5],
}

impl GoProState {
    /// Encoded length.
    pub const LEN: usize = 36;

    fn put(&self, dst: &mut BytesMut) {
        dst.put_slice(&[
            self.version,
            self.model,
            self.status,
            self.recording,
            self.capture_mode,
            self.ntsc_pal,
            self.video_resolution,
            self.video_fps,
            self.video_fov,
            self.video_low_light,
            self.photo_resolution,
            self.photo_burst_rate,
            self.video_protune,
            self.video_white_balance,
            self.video_color,
            self.video_gain,
            self.video_sharpness,
            self.video_exposure,
            self.gimbal_enabled,
        ]);
        dst.put_slice(&self.extra_u8);
        for v in self.extra_u16 {
            dst.put_u16_le(v);
        }
    }

    fn read(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let b: [u8; 19] = r.bytes()?;
        let extra_u8: [u8; 7] = r.bytes()?;
        let mut extra_u16 = [0u16; 5];
        for v in &mut extra_u16 {
            *v = r.u16()?;
        }
        Ok(GoProState {
            version: b[0],
            model: b[1],
            status: b[2],
            recording: b[3],
            capture_mode: b[4],
            ntsc_pal: b[5],
            video_resolution: b[6],
            video_fps: b[7],
            video_fov: b[8],
            video_low_light: b[9],
            photo_resolution: b[10],
            photo_burst_rate: b[11],
            video_protune: b[12],
            video_white_balance: b[13],
            video_color: b[14],
            video_gain: b[15],
            video_sharpness: b[16],
            video_exposure: b[17],
            gimbal_enabled: b[18],
            extra_u8,
            extra_u16,
        })
    }
}

pub(crate) fn encode(msg: &SoloMessage, dst: &mut BytesMut) {
    use SoloMessage as M;
    match msg {
        M::GoProSetEnabled(v) | M::GoProRecord(v) => dst.put_u32_le(*v),
        M::GoProSetRequest { command, value } => {
            dst.put_u16_le(*command);
            dst.put_u16_le(*value);
        }
        M::GoProV1State(s) | M::GoProV2State(s) => s.put(dst),
        M::GoProSetExtendedRequest { command, value } => {
            dst.put_u16_le(*command);
            dst.put_slice(value);
        }
        M::GoProPhoto {
            lat_deg,
            lon_deg,
            alt_m,
            time,
        } => {
            dst.put_f64_le(*lat_deg);
            dst.put_f64_le(*lon_deg);
            dst.put_f32_le(*alt_m);
            dst.put_u32_le(*time);
        }
        M::GoProRequestState => {}
        other => debug_assert!(false, "{} is not a GoPro message", other.name()),
    }
}

pub(crate) fn decode(r: &mut Reader<'_>) -> Result<SoloMessage, DecodeError> {
    Ok(match r.msg_type() {
        ids::GOPRO_SET_ENABLED => SoloMessage::GoProSetEnabled(r.u32_in("enabled", 0, 1)?),
        // Command and value are the GoPro MAVLink request's; the engine checks them.
        ids::GOPRO_SET_REQUEST => SoloMessage::GoProSetRequest {
            command: r.u16()?,
            value: r.u16()?,
        },
        ids::GOPRO_RECORD => SoloMessage::GoProRecord(r.u32_in("on_off", 0, 2)?),
        ids::GOPRO_V1_STATE => SoloMessage::GoProV1State(GoProState::read(r)?),
        ids::GOPRO_V2_STATE => SoloMessage::GoProV2State(GoProState::read(r)?),
        ids::GOPRO_REQUEST_STATE => SoloMessage::GoProRequestState,
        ids::GOPRO_SET_EXTENDED_REQUEST => SoloMessage::GoProSetExtendedRequest {
            command: r.u16()?,
            value: r.bytes()?,
        },
        ids::GOPRO_PHOTO => SoloMessage::GoProPhoto {
            lat_deg: r.lat("latitude")?,
            lon_deg: r.lon("longitude")?,
            alt_m: r.f32("altitude")?,
            time: r.u32()?,
        },
        other => return Err(DecodeError::UnknownType(other)),
    })
}
