//! Message type ids (`messageType` on the wire). The specification's tables get
//! several wrong (PANO_OPTIONS and ZIPLINE_OPTIONS both say 119); these follow
//! FACTS.md, i.e. the reference ShotManager (`app_packet.py`).

// General messages.
pub const GET_CURRENT_SHOT: u32 = 0;
pub const SET_CURRENT_SHOT: u32 = 1;
pub const LOCATION: u32 = 2;
pub const RECORD_POSITION: u32 = 3;
pub const CABLE_CAM_OPTIONS: u32 = 4;
pub const GET_BUTTON_SETTING: u32 = 5;
pub const SET_BUTTON_SETTING: u32 = 6;
pub const PAUSE: u32 = 7;

// Shot options and state.
pub const FOLLOW_OPTIONS: u32 = 19;
pub const FOLLOW_OPTIONS_V2: u32 = 119;
pub const SHOT_OPTIONS: u32 = 20;
pub const SHOT_ERROR: u32 = 21;
pub const PANO_OPTIONS: u32 = 22;
pub const ZIPLINE_OPTIONS: u32 = 23;
pub const REWIND_OPTIONS: u32 = 24;
pub const PANO_STATE: u32 = 25;
pub const HOME_LOCATION: u32 = 26;
pub const ZIPLINE_LOCK: u32 = 28;

// Multipoint cable cam.
pub const SPLINE_RECORD: u32 = 50;
pub const SPLINE_PLAY: u32 = 51;
pub const SPLINE_POINT: u32 = 52;
pub const SPLINE_SEEK: u32 = 53;
pub const SPLINE_PLAYBACK_STATUS: u32 = 54;
pub const SPLINE_PATH_SETTINGS: u32 = 55;
pub const SPLINE_DURATIONS: u32 = 56;
pub const SPLINE_ATTACH: u32 = 57;

// ShotManager to app.
pub const SHOTMANAGER_ERROR: u32 = 1000;
pub const CABLE_CAM_WAYPOINT: u32 = 1001;
pub const SECOND_PHONE_NOTIFICATION: u32 = 1002;

// Geofence.
pub const GEOFENCE_SET_DATA: u32 = 3000;
pub const GEOFENCE_SET_ACK: u32 = 3001;
pub const GEOFENCE_UPDATE_POLY: u32 = 3002;
pub const GEOFENCE_CLEAR: u32 = 3003;
pub const GEOFENCE_ACTIVATED: u32 = 3004;

// GoPro.
pub const GOPRO_SET_ENABLED: u32 = 5000;
pub const GOPRO_SET_REQUEST: u32 = 5001;
pub const GOPRO_RECORD: u32 = 5003;
pub const GOPRO_V1_STATE: u32 = 5005;
pub const GOPRO_V2_STATE: u32 = 5006;
pub const GOPRO_REQUEST_STATE: u32 = 5007;
pub const GOPRO_SET_EXTENDED_REQUEST: u32 = 5009;
pub const GOPRO_PHOTO: u32 = 5020;

// Site Scan.
pub const INSPECT_START: u32 = 10001;
pub const INSPECT_SET_WAYPOINT: u32 = 10002;
pub const INSPECT_MOVE_GIMBAL: u32 = 10003;
pub const INSPECT_MOVE_VEHICLE: u32 = 10004;
pub const SCAN_START: u32 = 10101;
pub const SURVEY_START: u32 = 10201;
