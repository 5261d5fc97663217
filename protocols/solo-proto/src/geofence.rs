//! Geofence messages: the app's polygons (JSON), ShotManager's ack, single-vertex
//! updates, clear and activation notices.

use bytes::{BufMut, BytesMut};
use serde::{Deserialize, Serialize};

use crate::error::DecodeError;
use crate::ids;
use crate::message::SoloMessage;
use crate::wire::{check_lat_lon, Reader};

/// GEOFENCE_SET_DATA's JSON blob: three arrays of equal length, one entry per
/// polygon. Vertices are `[lat, lon]` in degrees, counter-clockwise.
///
/// The codec checks the shape (equal lengths, valid coordinates, known kinds) and
/// accepts any number of polygons; polygon geometry is the engine's to judge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GeofenceData {
    /// The fence polygons.
    pub coord: Vec<Vec<[f64; 2]>>,
    /// Each polygon's inner (warning) polygon.
    #[serde(rename = "subCoord")]
    pub sub_coord: Vec<Vec<[f64; 2]>>,
    /// Per polygon: 0 inclusive (keep in), 1 exclusive (keep out).
    #[serde(rename = "type")]
    pub kinds: Vec<u8>,
}

impl GeofenceData {
    fn check(&self, msg_type: u32) -> Result<(), DecodeError> {
        let invalid = |what: String| crate::wire::invalid(msg_type, what);
        if self.coord.len() != self.sub_coord.len() || self.coord.len() != self.kinds.len() {
            return Err(invalid(format!(
                "coord, subCoord and type have different sizes ({}, {}, {})",
                self.coord.len(),
                self.sub_coord.len(),
                self.kinds.len()
            )));
        }
        for (i, kind) in self.kinds.iter().enumerate() {
            if *kind > 1 {
                return Err(invalid(format!("type[{i}] is {kind}, expected 0 or 1")));
            }
        }
        for (key, polygons) in [("coord", &self.coord), ("subCoord", &self.sub_coord)] {
            for (i, polygon) in polygons.iter().enumerate() {
                for (j, [lat, lon]) in polygon.iter().enumerate() {
                    check_lat_lon(msg_type, &format!("{key}[{i}][{j}]"), *lat, *lon)?;
                }
            }
        }
        Ok(())
    }
}

pub(crate) fn encode(msg: &SoloMessage, dst: &mut BytesMut) {
    use SoloMessage as M;
    match msg {
        M::GeofenceSetData(data) => {
            // Serialising plain numbers and vectors into memory cannot fail; a NaN
            // (never produced by decode) becomes `null`, which the peer refuses.
            if let Ok(json) = serde_json::to_vec(data) {
                dst.put_slice(&json);
            }
        }
        M::GeofenceSetAck { count, valid } => {
            dst.put_u16_le(*count);
            dst.put_u8(u8::from(*valid));
        }
        M::GeofenceUpdatePoly {
            action,
            polygon_index,
            vertex_index,
            lat_deg,
            lon_deg,
            sub_lat_deg,
            sub_lon_deg,
        } => {
            dst.put_u8(*action);
            dst.put_u16_le(*polygon_index);
            dst.put_u16_le(*vertex_index);
            dst.put_f64_le(*lat_deg);
            dst.put_f64_le(*lon_deg);
            dst.put_f64_le(*sub_lat_deg);
            dst.put_f64_le(*sub_lon_deg);
        }
        M::GeofenceClear | M::GeofenceActivated => {}
        other => debug_assert!(false, "{} is not a geofence message", other.name()),
    }
}

/// GEOFENCE_UPDATE_POLY action that removes a vertex (its coordinates are ignored).
const ACTION_REMOVE: u8 = 2;

pub(crate) fn decode(r: &mut Reader<'_>) -> Result<SoloMessage, DecodeError> {
    Ok(match r.msg_type() {
        ids::GEOFENCE_SET_DATA => {
            let data: GeofenceData = serde_json::from_slice(r.take_rest())
                .map_err(|e| r.invalid(format!("malformed JSON: {e}")))?;
            data.check(r.msg_type())?;
            SoloMessage::GeofenceSetData(data)
        }
        ids::GEOFENCE_SET_ACK => SoloMessage::GeofenceSetAck {
            count: r.u16()?,
            valid: r.u8_in("valid", 0, 1)? == 1,
        },
        ids::GEOFENCE_UPDATE_POLY => {
            let action = r.u8_in("action", 0, 2)?;
            let polygon_index = r.u16()?;
            let vertex_index = r.u16()?;
            let [lat_deg, lon_deg, sub_lat_deg, sub_lon_deg] =
                [r.bytes()?, r.bytes()?, r.bytes()?, r.bytes()?].map(f64::from_le_bytes);
            if action != ACTION_REMOVE {
                check_lat_lon(r.msg_type(), "vertex", lat_deg, lon_deg)?;
                check_lat_lon(r.msg_type(), "sub-polygon vertex", sub_lat_deg, sub_lon_deg)?;
            }
            SoloMessage::GeofenceUpdatePoly {
                action,
                polygon_index,
                vertex_index,
                lat_deg,
                lon_deg,
                sub_lat_deg,
                sub_lon_deg,
            }
        }
        ids::GEOFENCE_CLEAR => SoloMessage::GeofenceClear,
        ids::GEOFENCE_ACTIVATED => SoloMessage::GeofenceActivated,
        other => return Err(DecodeError::UnknownType(other)),
    })
}
