//! Shot indices carried by GET/SET_CURRENT_SHOT and button settings (FACTS.md; the
//! reference `shots.py`). Site-scan shots (inspect, scan, survey) have no index:
//! they are entered through their own START messages.

pub const NONE: i32 = -1;
pub const SELFIE: i32 = 0;
pub const ORBIT: i32 = 1;
pub const CABLECAM: i32 = 2;
pub const ZIPLINE: i32 = 3;
pub const FOLLOW: i32 = 5;
pub const MULTIPOINT: i32 = 6;
pub const PANO: i32 = 7;
pub const REWIND: i32 = 8;
pub const TRANSECT: i32 = 9;
pub const RTL: i32 = 10;

/// The lowest index a message may carry (no shot).
pub const MIN: i32 = NONE;
/// The highest index a message may carry. 4 (the reference's unused "record" shot)
/// lies inside the range and is accepted; the engine refuses shots it does not fly.
pub const MAX: i32 = RTL;

/// Stable snake_case name of a shot index, for logs and metrics.
pub fn name(shot: i32) -> Option<&'static str> {
    Some(match shot {
        NONE => "none",
        SELFIE => "selfie",
        ORBIT => "orbit",
        CABLECAM => "cablecam",
        ZIPLINE => "zipline",
        4 => "record",
        FOLLOW => "follow",
        MULTIPOINT => "multipoint",
        PANO => "pano",
        REWIND => "rewind",
        TRANSECT => "transect",
        RTL => "rtl",
        _ => return None,
    })
}
