//! Solo messages as one human-readable line (`GET_CURRENT_SHOT shot=orbit(1)`), and
//! the names people type for shots and buttons.

use skymesh_ipc_types::Button;
use solo_proto::{shots, GoProState, Location, SoloMessage};

/// `orbit(1)`, or `shot(42)` for an index without a name.
pub fn shot(index: i32) -> String {
    match shots::name(index) {
        Some(name) => format!("{name}({index})"),
        None => format!("shot({index})"),
    }
}

/// A shot by name (`orbit`, `cable-cam`, …) or index (`1`, `-1`), within the range
/// the protocol accepts.
pub fn parse_shot(s: &str) -> Option<i32> {
    let key: String = s
        .to_ascii_lowercase()
        .chars()
        .filter(|c| *c != '-' && *c != '_')
        .collect();
    let range = shots::MIN..=shots::MAX;
    if let Some(i) = range
        .clone()
        .find(|i| shots::name(*i) == Some(key.as_str()))
    {
        return Some(i);
    }
    s.parse().ok().filter(|i| range.contains(i))
}

/// `a(4)`, or `button(42)` for an unknown number.
pub fn button(index: i32) -> String {
    match u8::try_from(index)
        .ok()
        .and_then(|b| Button::try_from(b).ok())
    {
        Some(b) => format!("{}({index})", b.as_str()),
        None => format!("button({index})"),
    }
}

fn location(l: &Location) -> String {
    format!("lat={} lon={} alt={}m", l.lat_deg, l.lon_deg, l.alt_m)
}

fn gopro(s: &GoProState) -> String {
    let status = match s.status {
        0 => "no_gopro",
        1 => "incompatible",
        2 => "connected",
        3 => "error",
        _ => "unknown",
    };
    format!(
        "version={} status={status}({}) recording={} capture_mode={} gimbal_enabled={}",
        s.version, s.status, s.recording, s.capture_mode, s.gimbal_enabled
    )
}

/// Field text of a message (empty for messages without fields).
fn fields(m: &SoloMessage) -> String {
    use SoloMessage as M;
    match m {
        M::GetCurrentShot(s) | M::SetCurrentShot(s) => format!("shot={}", shot(*s)),
        M::Location(l) | M::HomeLocation(l) => location(l),
        M::CableCamOptions {
            cam_interpolation,
            yaw_direction_cw,
            cruise_speed,
        } => format!(
            "interpolate={cam_interpolation} cw={yaw_direction_cw} speed={cruise_speed}m/s"
        ),
        M::GetButtonSetting(b) | M::SetButtonSetting(b) => format!(
            "button={} event={} shot={} mode={}",
            button(b.button),
            b.event,
            shot(b.shot),
            b.mode
        ),
        M::FollowOptions {
            cruise_speed,
            look_at,
        } => format!("speed={cruise_speed}m/s look_at={look_at}"),
        M::FollowOptionsV2 {
            cruise_speed,
            look_at,
            follow_preference,
        } => {
            let pref = match follow_preference {
                0 => "hold",
                1 => "free",
                2 => "leash",
                _ => "unknown",
            };
            format!("speed={cruise_speed}m/s look_at={look_at} preference={pref}({follow_preference})")
        }
        M::ShotOptions { cruise_speed } => format!("speed={cruise_speed}m/s"),
        M::ShotError(e) => {
            let what = match e {
                0 => "bad_ekf",
                1 => "unarmed",
                2 => "rtl",
                _ => "unknown",
            };
            format!("error={what}({e})")
        }
        M::PanoOptions {
            pano_type,
            run_state,
            cylinder_fov,
            deg_second_yaw,
            lens_fov,
        } => format!("type={pano_type} run_state={run_state} cylinder_fov={cylinder_fov} yaw_rate={deg_second_yaw}deg/s lens_fov={lens_fov}"),
        M::ZiplineOptions {
            cruise_speed,
            is_3d,
            cam_pointing,
        } => format!("speed={cruise_speed}m/s 3d={is_3d} cam_pointing={cam_pointing}"),
        M::RewindOptions {
            enabled,
            hover,
            rewind_distance,
        } => format!("enabled={enabled} hover={hover} distance={rewind_distance}m"),
        M::PanoState { index, total } => format!("index={index} total={total}"),
        M::SplinePoint(p) => format!(
            "index={} lat={} lon={} alt={}m pitch={} yaw={} u={} status={}",
            p.index, p.lat_deg, p.lon_deg, p.alt_m, p.pitch_deg, p.yaw_deg, p.u_position, p.status
        ),
        M::SplineSeek {
            u_position,
            cruise_state,
        }
        | M::SplinePlaybackStatus {
            u_position,
            cruise_state,
        } => format!("u={u_position} cruise_state={cruise_state}"),
        M::SplinePathSettings {
            camera_control,
            desired_time_s,
        } => format!("camera_control={camera_control} time={desired_time_s}s"),
        M::SplineDurations {
            min_time_s,
            max_time_s,
        } => format!("min={min_time_s}s max={max_time_s}s"),
        M::SplineAttach(i) => format!("keypoint={i}"),
        M::ShotManagerError(text) => format!("{text:?}"),
        M::CableCamWaypoint {
            lat_deg,
            lon_deg,
            alt_m,
            yaw_deg,
            pitch_deg,
        } => format!("lat={lat_deg} lon={lon_deg} alt={alt_m}m yaw={yaw_deg} pitch={pitch_deg}"),
        M::GeofenceSetData(d) => format!("polygons={}", d.coord.len()),
        M::GeofenceSetAck { count, valid } => format!("count={count} valid={valid}"),
        M::GeofenceUpdatePoly {
            action,
            polygon_index,
            vertex_index,
            lat_deg,
            lon_deg,
            ..
        } => format!("action={action} polygon={polygon_index} vertex={vertex_index} lat={lat_deg} lon={lon_deg}"),
        M::GoProSetEnabled(on) => format!("enabled={on}"),
        M::GoProSetRequest { command, value } => format!("command={command} value={value}"),
        M::GoProRecord(r) => {
            let what = match r {
                0 => "stop",
                1 => "start",
                2 => "toggle",
                _ => "unknown",
            };
            format!("record={what}({r})")
        }
        M::GoProV1State(s) | M::GoProV2State(s) => gopro(s),
        M::GoProSetExtendedRequest { command, value } => format!("command={command} value={value:?}"),
        M::GoProPhoto {
            lat_deg,
            lon_deg,
            alt_m,
            time,
        } => format!("lat={lat_deg} lon={lon_deg} alt={alt_m}m time={time}"),
        M::InspectStart { takeoff_alt_m } => format!("takeoff_alt={takeoff_alt_m}m"),
        M::InspectSetWaypoint {
            lat_deg,
            lon_deg,
            alt_m,
        } => format!("lat={lat_deg} lon={lon_deg} alt={alt_m}m"),
        M::InspectMoveGimbal {
            pitch_deg,
            roll_deg,
            yaw_deg,
        } => format!("pitch={pitch_deg} roll={roll_deg} yaw={yaw_deg}"),
        M::InspectMoveVehicle { vx, vy, vz } => format!("vx={vx} vy={vy} vz={vz}"),
        M::RecordPosition
        | M::Pause
        | M::ZiplineLock
        | M::SplineRecord
        | M::SplinePlay
        | M::SecondPhoneNotification
        | M::GeofenceClear
        | M::GeofenceActivated
        | M::GoProRequestState
        | M::ScanStart
        | M::SurveyStart => String::new(),
    }
}

/// One line: the message name in capitals, then its fields.
pub fn describe(m: &SoloMessage) -> String {
    let name = m.name().to_ascii_uppercase();
    let fields = fields(m);
    if fields.is_empty() {
        name
    } else {
        format!("{name} {fields}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_are_readable() {
        assert_eq!(
            describe(&SoloMessage::GetCurrentShot(1)),
            "GET_CURRENT_SHOT shot=orbit(1)"
        );
        assert_eq!(
            describe(&SoloMessage::SetCurrentShot(-1)),
            "SET_CURRENT_SHOT shot=none(-1)"
        );
        assert_eq!(
            describe(&SoloMessage::ShotOptions { cruise_speed: 2.5 }),
            "SHOT_OPTIONS speed=2.5m/s"
        );
        assert_eq!(describe(&SoloMessage::Pause), "PAUSE");
    }

    #[test]
    fn shots_and_buttons_by_name_or_number() {
        assert_eq!(parse_shot("orbit"), Some(1));
        assert_eq!(parse_shot("Cable-Cam"), Some(2));
        assert_eq!(parse_shot("none"), Some(-1));
        assert_eq!(parse_shot("6"), Some(6));
        assert_eq!(parse_shot("-1"), Some(-1));
        assert_eq!(parse_shot("warp"), None);
        assert_eq!(parse_shot("-5"), None);
        assert_eq!(shot(42), "shot(42)");
        assert_eq!(button(4), "a(4)");
        assert_eq!(button(99), "button(99)");
    }
}
