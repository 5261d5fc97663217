//! The encoding of [`ShotRequest`] and [`ShotEvent`] bodies (see the parent
//! module's docs): one table per enum gives each variant its kind tag, its log
//! label and its fields in wire order; `shot_kinds!` turns a table into `name`,
//! `encode` and `decode`, so a variant's layout is written down once.

use super::body::{Field, Lat, Lon, Reader, Writer};
use super::{
    ButtonSetting, GoProState, Location, ShotDecodeError, ShotEvent, ShotRequest, SplinePoint,
};

/// The pattern that binds a variant's fields (tuple fields by the table's names).
macro_rules! kind_pattern {
    ($E:ident $V:ident) => {
        $E::$V
    };
    ($E:ident $V:ident ($($b:ident : $T:ty $(= $label:literal)?),*)) => {
        $E::$V($($b),*)
    };
    ($E:ident $V:ident {$($f:ident : $T:ty $(= $label:literal)?),*}) => {
        $E::$V { $($f),* }
    };
}

/// Writes the fields bound by `kind_pattern!`, in order.
macro_rules! put_fields {
    ($w:ident) => {};
    ($w:ident ($($b:ident : $T:ty $(= $label:literal)?),*)) => {
        $(<$T as Field>::put($b, $w);)*
    };
    ($w:ident {$($f:ident : $T:ty $(= $label:literal)?),*}) => {
        $(<$T as Field>::put($f, $w);)*
    };
}

/// Reads the fields in order and builds the variant.
macro_rules! take_fields {
    ($r:ident $E:ident $V:ident) => {
        $E::$V
    };
    ($r:ident $E:ident $V:ident ($($b:ident : $T:ty $(= $label:literal)?),*)) => {
        $E::$V($(<$T as Field>::take($r, concat!("" $(, $label)?))?),*)
    };
    ($r:ident $E:ident $V:ident {$($f:ident : $T:ty $(= $label:literal)?),*}) => {
        $E::$V { $($f: <$T as Field>::take($r, concat!("" $(, $label)?))?),* }
    };
}

/// `Enum { tag "label" Variant fields; … }` → `Enum::name`, `Enum::encode` and
/// `Enum::decode`. Fields are `name: Encoding` (see [`Field`]), `= "label"` where
/// the encoding checks the value; tuple fields are named for the table only.
macro_rules! shot_kinds {
    ($E:ident {
        $($tag:literal $name:literal $V:ident $(($($tuple:tt)*))? $({$($named:tt)*})?;)*
    }) => {
        impl $E {
            /// Stable snake_case label for logs and metrics.
            pub fn name(&self) -> &'static str {
                match self {
                    $($E::$V { .. } => $name,)*
                }
            }

            /// Writes the fields; returns the kind tag.
            pub(super) fn encode(&self, w: &mut Writer) -> u16 {
                match self {
                    $(kind_pattern!($E $V $(($($tuple)*))? $({$($named)*})?) => {
                        put_fields!(w $(($($tuple)*))? $({$($named)*})?);
                        $tag
                    })*
                }
            }

            pub(super) fn decode(kind: u16, r: &mut Reader<'_>) -> Result<$E, ShotDecodeError> {
                Ok(match kind {
                    $($tag => take_fields!(r $E $V $(($($tuple)*))? $({$($named)*})?),)*
                    other => return Err(ShotDecodeError::UnknownKind(other)),
                })
            }
        }
    };
}

shot_kinds!(ShotRequest {
    1 "start_shot" StartShot(shot: i32);
    2 "location" Location(l: Location);
    3 "record_position" RecordPosition;
    4 "cable_options" CableOptions {
        cam_interpolation: u16,
        yaw_direction_cw: u16,
        cruise_speed: f32 = "cruise_speed"
    };
    5 "get_button_setting" GetButtonSetting(b: ButtonSetting);
    6 "set_button_setting" SetButtonSetting(b: ButtonSetting);
    7 "pause" Pause;
    8 "follow_options" FollowOptions { cruise_speed: f32 = "cruise_speed", look_at: i32 };
    9 "follow_options_v2" FollowOptionsV2 {
        cruise_speed: f32 = "cruise_speed",
        look_at: i32,
        follow_preference: i32
    };
    10 "shot_options" ShotOptions { cruise_speed: f32 = "cruise_speed" };
    11 "gopro_set_enabled" GoProSetEnabled(on: u32);
    12 "gopro_set_request" GoProSetRequest { command: u16, value: u16 };
    13 "gopro_set_extended_request" GoProSetExtendedRequest { command: u16, value: [u8; 4] };
    14 "gopro_record" GoProRecord(action: u32);
    15 "gopro_request_state" GoProRequestState;
    16 "spline_point" SplinePoint(p: SplinePoint);
    17 "geofence_update_poly" GeofenceUpdatePoly {
        action: u8,
        polygon_index: u16,
        vertex_index: u16,
        lat_deg: Lat = "latitude",
        lon_deg: Lon = "longitude",
        sub_lat_deg: Lat = "sub latitude",
        sub_lon_deg: Lon = "sub longitude"
    };
    18 "geofence_clear" GeofenceClear;
    19 "spline_record" SplineRecord;
    20 "spline_play" SplinePlay;
    21 "spline_seek" SplineSeek { u_position: f32 = "u_position", cruise_state: i32 };
    22 "spline_path_settings" SplinePathSettings {
        camera_control: u32,
        desired_time_s: f32 = "desired_time"
    };
    23 "spline_attach" SplineAttach(index: u32);
    24 "zipline_options" ZiplineOptions {
        cruise_speed: f32 = "cruise_speed",
        is_3d: u8,
        cam_pointing: u8
    };
    25 "zipline_lock" ZiplineLock;
    26 "pano_options" PanoOptions {
        pano_type: u8,
        run_state: u8,
        cylinder_fov: i16,
        deg_second_yaw: f32 = "deg_second_yaw",
        lens_fov: f32 = "lens_fov"
    };
    27 "rewind_options" RewindOptions {
        enabled: u8,
        hover: u8,
        rewind_distance: f32 = "rewind_distance"
    };
    28 "home_location" HomeLocation(l: Location);
    29 "inspect_start" InspectStart { takeoff_alt_m: f32 = "takeoff_alt" };
    30 "inspect_set_waypoint" InspectSetWaypoint {
        lat_deg: f32 = "latitude",
        lon_deg: f32 = "longitude",
        alt_m: f32 = "altitude"
    };
    31 "inspect_move_gimbal" InspectMoveGimbal {
        pitch_deg: f32 = "pitch",
        roll_deg: f32 = "roll",
        yaw_deg: f32 = "yaw"
    };
    32 "inspect_move_vehicle" InspectMoveVehicle { vx: f32 = "vx", vy: f32 = "vy", vz: f32 = "vz" };
    33 "scan_start" ScanStart;
    34 "survey_start" SurveyStart;
});

shot_kinds!(ShotEvent {
    1 "current_shot" CurrentShot(shot: i32);
    2 "refused" Refused(code: u32);
    3 "error" Error(text: String);
    4 "location" Location(l: Location);
    5 "home_location" HomeLocation(l: Location);
    6 "button_setting" ButtonSetting(b: ButtonSetting);
    7 "pause" Pause;
    8 "cable_options" CableOptions {
        cam_interpolation: u16,
        yaw_direction_cw: u16,
        cruise_speed: f32 = "cruise_speed"
    };
    9 "follow_options" FollowOptions { cruise_speed: f32 = "cruise_speed", look_at: i32 };
    10 "follow_options_v2" FollowOptionsV2 {
        cruise_speed: f32 = "cruise_speed",
        look_at: i32,
        follow_preference: i32
    };
    11 "shot_options" ShotOptions { cruise_speed: f32 = "cruise_speed" };
    12 "pano_options" PanoOptions {
        pano_type: u8,
        run_state: u8,
        cylinder_fov: i16,
        deg_second_yaw: f32 = "deg_second_yaw",
        lens_fov: f32 = "lens_fov"
    };
    13 "zipline_options" ZiplineOptions {
        cruise_speed: f32 = "cruise_speed",
        is_3d: u8,
        cam_pointing: u8
    };
    14 "rewind_options" RewindOptions {
        enabled: u8,
        hover: u8,
        rewind_distance: f32 = "rewind_distance"
    };
    15 "pano_state" PanoState { index: u8, total: u8 };
    16 "gopro_v1_state" GoProV1State(s: GoProState);
    17 "gopro_v2_state" GoProV2State(s: GoProState);
    18 "geofence_set_ack" GeofenceSetAck { count: u16, valid: bool };
    19 "geofence_activated" GeofenceActivated;
    20 "geofence_clear" GeofenceClear;
    21 "cable_cam_waypoint" CableCamWaypoint {
        lat_deg: Lat = "latitude",
        lon_deg: Lon = "longitude",
        alt_m: f32 = "altitude",
        yaw_deg: f32 = "yaw",
        pitch_deg: f32 = "pitch"
    };
    22 "spline_point" SplinePoint(p: SplinePoint);
    23 "spline_play" SplinePlay;
    24 "spline_playback_status" SplinePlaybackStatus {
        u_position: f32 = "u_position",
        cruise_state: i32
    };
    25 "spline_durations" SplineDurations {
        min_time_s: f32 = "min_time",
        max_time_s: f32 = "max_time"
    };
    26 "spline_attach" SplineAttach(index: u32);
});
