//! What the protocol says about each type id, in one table: its metric name, value
//! length, who sends it and which family file reads it.

use crate::ids;
use crate::MAX_VALUE_LEN;

/// The value length a type id requires.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueLen {
    Exact(usize),
    Variable { max: usize },
}

impl ValueLen {
    /// Whether a value of `len` bytes has an acceptable length.
    pub fn accepts(self, len: usize) -> bool {
        match self {
            ValueLen::Exact(n) => len == n,
            ValueLen::Variable { max } => len <= max,
        }
    }
}

/// Who sends a message (the specification's "Sent by" lines, corrected where the
/// shot flows contradict them; see [`direction`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Only the app sends it; ShotManager (skymesh) never does.
    AppToVehicle,
    /// Only ShotManager sends it; the gateway drops it when an app sends it.
    VehicleToApp,
    Both,
}

impl Direction {
    /// Whether the app may send this message to the vehicle.
    pub fn from_app(self) -> bool {
        matches!(self, Direction::AppToVehicle | Direction::Both)
    }

    /// Whether the vehicle may send this message to the app.
    pub fn to_app(self) -> bool {
        matches!(self, Direction::VehicleToApp | Direction::Both)
    }
}

/// Which family file decodes a type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Family {
    General,
    Options,
    Spline,
    GoPro,
    Geofence,
    SiteScan,
}

#[derive(Debug, Clone, Copy)]
pub(crate) struct Entry {
    pub msg_type: u32,
    pub name: &'static str,
    pub len: ValueLen,
    pub direction: Direction,
    pub family: Family,
}

const fn e(
    msg_type: u32,
    name: &'static str,
    len: ValueLen,
    direction: Direction,
    family: Family,
) -> Entry {
    Entry {
        msg_type,
        name,
        len,
        direction,
        family,
    }
}

use Direction::{AppToVehicle as A2V, Both, VehicleToApp as V2A};
use Family::*;
use ValueLen::Exact as X;

const VARIABLE: ValueLen = ValueLen::Variable { max: MAX_VALUE_LEN };

/// Every known type. Directions follow the spec's "Sent by" lines except:
/// SHOT_OPTIONS is both (the orbit flow has the app send it, the table says only
/// ShotManager does); LOCATION is both (the engine echoes the orbit/zipline ROI);
/// options messages the spec marks "bidirectional" are both; SPLINE_PLAY, SPLINE_POINT,
/// SPLINE_ATTACH, SOLO_PAUSE and GEOFENCE_CLEAR are both. Absent from the spec, per
/// the reference: PANO_STATE is sent by ShotManager; HOME_LOCATION both (ShotManager
/// reports home, the app moves it for "return to me"); REWIND_OPTIONS both.
pub(crate) const CATALOG: &[Entry] = &[
    e(
        ids::GET_CURRENT_SHOT,
        "get_current_shot",
        X(4),
        V2A,
        General,
    ),
    e(
        ids::SET_CURRENT_SHOT,
        "set_current_shot",
        X(4),
        A2V,
        General,
    ),
    e(ids::LOCATION, "location", X(20), Both, General),
    e(ids::RECORD_POSITION, "record_position", X(0), A2V, General),
    e(
        ids::CABLE_CAM_OPTIONS,
        "cable_cam_options",
        X(8),
        Both,
        Options,
    ),
    e(
        ids::GET_BUTTON_SETTING,
        "get_button_setting",
        X(16),
        Both,
        General,
    ),
    e(
        ids::SET_BUTTON_SETTING,
        "set_button_setting",
        X(16),
        A2V,
        General,
    ),
    // The spec's table says 8 but lists no field; the reference app (DroneKit-Android
    // `SoloPause`) and ShotManager send an empty value.
    e(ids::PAUSE, "pause", X(0), Both, General),
    e(ids::FOLLOW_OPTIONS, "follow_options", X(8), Both, Options),
    e(
        ids::FOLLOW_OPTIONS_V2,
        "follow_options_v2",
        X(12),
        Both,
        Options,
    ),
    e(ids::SHOT_OPTIONS, "shot_options", X(4), Both, Options),
    e(ids::SHOT_ERROR, "shot_error", X(4), V2A, General),
    e(ids::PANO_OPTIONS, "pano_options", X(12), Both, Options),
    e(ids::ZIPLINE_OPTIONS, "zipline_options", X(6), Both, Options),
    e(ids::REWIND_OPTIONS, "rewind_options", X(6), Both, Options),
    e(ids::PANO_STATE, "pano_state", X(2), V2A, Options),
    e(ids::HOME_LOCATION, "home_location", X(20), Both, General),
    e(ids::ZIPLINE_LOCK, "zipline_lock", X(0), A2V, Options),
    e(ids::SPLINE_RECORD, "spline_record", X(0), A2V, Spline),
    e(ids::SPLINE_PLAY, "spline_play", X(0), Both, Spline),
    e(ids::SPLINE_POINT, "spline_point", X(44), Both, Spline),
    e(ids::SPLINE_SEEK, "spline_seek", X(8), A2V, Spline),
    e(
        ids::SPLINE_PLAYBACK_STATUS,
        "spline_playback_status",
        X(8),
        V2A,
        Spline,
    ),
    e(
        ids::SPLINE_PATH_SETTINGS,
        "spline_path_settings",
        X(8),
        A2V,
        Spline,
    ),
    e(ids::SPLINE_DURATIONS, "spline_durations", X(8), V2A, Spline),
    e(ids::SPLINE_ATTACH, "spline_attach", X(4), Both, Spline),
    e(
        ids::SHOTMANAGER_ERROR,
        "shotmanager_error",
        VARIABLE,
        V2A,
        General,
    ),
    e(
        ids::CABLE_CAM_WAYPOINT,
        "cable_cam_waypoint",
        X(28),
        V2A,
        General,
    ),
    e(
        ids::SECOND_PHONE_NOTIFICATION,
        "second_phone_notification",
        X(0),
        V2A,
        General,
    ),
    e(
        ids::GEOFENCE_SET_DATA,
        "geofence_set_data",
        VARIABLE,
        A2V,
        Geofence,
    ),
    e(
        ids::GEOFENCE_SET_ACK,
        "geofence_set_ack",
        X(3),
        V2A,
        Geofence,
    ),
    e(
        ids::GEOFENCE_UPDATE_POLY,
        "geofence_update_poly",
        X(37),
        A2V,
        Geofence,
    ),
    e(ids::GEOFENCE_CLEAR, "geofence_clear", X(0), Both, Geofence),
    e(
        ids::GEOFENCE_ACTIVATED,
        "geofence_activated",
        X(0),
        V2A,
        Geofence,
    ),
    e(
        ids::GOPRO_SET_ENABLED,
        "gopro_set_enabled",
        X(4),
        A2V,
        GoPro,
    ),
    e(
        ids::GOPRO_SET_REQUEST,
        "gopro_set_request",
        X(4),
        A2V,
        GoPro,
    ),
    e(ids::GOPRO_RECORD, "gopro_record", X(4), A2V, GoPro),
    e(ids::GOPRO_V1_STATE, "gopro_v1_state", X(36), V2A, GoPro),
    e(ids::GOPRO_V2_STATE, "gopro_v2_state", X(36), V2A, GoPro),
    e(
        ids::GOPRO_REQUEST_STATE,
        "gopro_request_state",
        X(0),
        A2V,
        GoPro,
    ),
    e(
        ids::GOPRO_SET_EXTENDED_REQUEST,
        "gopro_set_extended_request",
        X(6),
        A2V,
        GoPro,
    ),
    e(ids::GOPRO_PHOTO, "gopro_photo", X(24), V2A, GoPro),
    e(ids::INSPECT_START, "inspect_start", X(4), A2V, SiteScan),
    e(
        ids::INSPECT_SET_WAYPOINT,
        "inspect_set_waypoint",
        X(12),
        A2V,
        SiteScan,
    ),
    e(
        ids::INSPECT_MOVE_GIMBAL,
        "inspect_move_gimbal",
        X(12),
        A2V,
        SiteScan,
    ),
    e(
        ids::INSPECT_MOVE_VEHICLE,
        "inspect_move_vehicle",
        X(12),
        A2V,
        SiteScan,
    ),
    e(ids::SCAN_START, "scan_start", X(0), A2V, SiteScan),
    e(ids::SURVEY_START, "survey_start", X(0), A2V, SiteScan),
];

pub(crate) fn entry(msg_type: u32) -> Option<&'static Entry> {
    CATALOG.iter().find(|e| e.msg_type == msg_type)
}

/// Metric name of a known type id (`"location"`, `"gopro_v2_state"`, …).
pub fn message_name(msg_type: u32) -> Option<&'static str> {
    entry(msg_type).map(|e| e.name)
}

/// The value length a type requires; `None` for an unknown type.
pub fn expected_len(msg_type: u32) -> Option<ValueLen> {
    entry(msg_type).map(|e| e.len)
}

/// Who may send a type; `None` for an unknown type.
pub fn direction(msg_type: u32) -> Option<Direction> {
    entry(msg_type).map(|e| e.direction)
}

/// Every known type id, in the catalog's order.
pub fn known_types() -> impl Iterator<Item = u32> {
    CATALOG.iter().map(|e| e.msg_type)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catalog_ids_and_names_are_unique() {
        for (i, a) in CATALOG.iter().enumerate() {
            for b in &CATALOG[i + 1..] {
                assert_ne!(a.msg_type, b.msg_type, "{} and {}", a.name, b.name);
                assert_ne!(a.name, b.name);
            }
        }
        assert_eq!(CATALOG.len(), 48);
    }

    #[test]
    fn directions_follow_the_spec() {
        assert_eq!(direction(ids::SHOT_OPTIONS), Some(Direction::Both));
        assert_eq!(direction(ids::LOCATION), Some(Direction::Both));
        assert_eq!(direction(ids::GET_BUTTON_SETTING), Some(Direction::Both));
        assert_eq!(
            direction(ids::SET_CURRENT_SHOT),
            Some(Direction::AppToVehicle)
        );
        assert_eq!(
            direction(ids::GET_CURRENT_SHOT),
            Some(Direction::VehicleToApp)
        );
        assert_eq!(
            direction(ids::GOPRO_V2_STATE),
            Some(Direction::VehicleToApp)
        );
        assert_eq!(direction(ids::ZIPLINE_LOCK), Some(Direction::AppToVehicle));
        assert_eq!(direction(9999), None);
        assert!(Direction::Both.from_app() && Direction::Both.to_app());
        assert!(!Direction::VehicleToApp.from_app());
        assert!(!Direction::AppToVehicle.to_app());
    }

    #[test]
    fn lengths_follow_facts() {
        assert_eq!(expected_len(ids::PAUSE), Some(ValueLen::Exact(0)));
        assert_eq!(expected_len(ids::PANO_OPTIONS), Some(ValueLen::Exact(12)));
        assert_eq!(expected_len(ids::SPLINE_POINT), Some(ValueLen::Exact(44)));
        assert_eq!(expected_len(ids::GOPRO_V1_STATE), Some(ValueLen::Exact(36)));
        assert_eq!(
            expected_len(ids::SHOTMANAGER_ERROR),
            Some(ValueLen::Variable { max: MAX_VALUE_LEN })
        );
        assert_eq!(expected_len(4242), None);
        assert_eq!(message_name(ids::GOPRO_V2_STATE), Some("gopro_v2_state"));
    }
}
