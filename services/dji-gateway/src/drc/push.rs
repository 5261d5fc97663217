//! The `drc/up` pushes, pure: osd_info_push and hsi_info_push from the link's
//! latest samples, delay_info_push from the measured command latency.
//!
//! osd_info_push: `attitude_head` is the vehicle's yaw (degrees, −180..180, the
//! heading over ground when no attitude has arrived); `latitude`/`longitude` WGS84;
//! `height` is the ellipsoid height DJI documents: the autopilot's altitude above
//! mean sea level plus its geoid undulation (`VehicleState::geoid_undulation_m`);
//! the MSL altitude alone while the autopilot reports no `alt_ellipsoid`;
//! `speed_x` north, `speed_y` east, `speed_z` UP (m/s); `gimbal_pitch`/`gimbal_roll`
//! the camera's (degrees, pitch down negative) and `gimbal_yaw` its heading over the
//! earth (vehicle yaw + the gimbal's yaw relative to the nose, −180..180), all 0 when
//! no gimbal reports. No push before the first vehicle position.
//!
//! hsi_info_push: skymesh has no obstacle sensors: every `*_enable`/`*_work` false and
//! every distance [`NO_OBSTACLE_DATA_MM`], the "no data" value of
//! `dji_proto::HsiInfoPush`, 360 entries around.
//!
//! delay_info_push (1 Hz): `sdr_cmd_delay` is the mean time from a drone_control's
//! arrival on `drc/down` to the arbiter's `CommandAck` for its setpoint, over the
//! acks of the last push period, in ms (rounded up, so a measured delay is ≥ 1);
//! 0 means no stick command was acknowledged in that period (nothing measured).
//! `liveview_delay_list` is empty: the gateway carries no video.

use std::time::Duration;

use dji_proto::{DelayInfoPush, HsiInfoPush, OsdInfoPush};
use skymesh_runtime::angle::wrap_180;

use crate::link::Snapshot;

/// Obstacle distance meaning "no data" (mm).
pub const NO_OBSTACLE_DATA_MM: i64 = 60_000;
/// Horizontal obstacle directions of hsi_info_push (one per degree).
pub const AROUND_DIRECTIONS: usize = 360;

/// Degrees into −180..180; an unknown (non-finite) angle is pushed as 0.
fn wrap_deg(deg: f64) -> f64 {
    let d = wrap_180(deg);
    if d.is_finite() {
        d
    } else {
        0.0
    }
}

/// osd_info_push data, `None` before the first vehicle position.
pub fn osd(snap: &Snapshot) -> Option<OsdInfoPush> {
    let s = snap.state.filter(|s| s.position_valid != 0)?;
    let head = if s.attitude_valid != 0 && s.yaw_rad.is_finite() {
        f64::from(s.yaw_rad).to_degrees()
    } else {
        f64::from(s.heading_deg)
    };
    let head = wrap_deg(head);
    let gimbal = snap.payload.filter(|p| p.is_gimbal_valid());
    let [n, e, d] = s.vel_ned_mps.map(f64::from);
    Some(OsdInfoPush {
        attitude_head: head,
        latitude: s.lat_deg,
        longitude: s.lon_deg,
        height: if s.alt_ellipsoid_valid != 0 && s.geoid_undulation_m.is_finite() {
            f64::from(s.alt_msl_m) + f64::from(s.geoid_undulation_m)
        } else {
            f64::from(s.alt_msl_m)
        },
        speed_x: n,
        speed_y: e,
        speed_z: -d,
        gimbal_pitch: gimbal.map_or(0.0, |g| f64::from(g.gimbal_pitch_deg)),
        gimbal_roll: gimbal.map_or(0.0, |g| f64::from(g.gimbal_roll_deg)),
        gimbal_yaw: gimbal.map_or(0.0, |g| wrap_deg(head + f64::from(g.gimbal_yaw_deg))),
    })
}

/// hsi_info_push data: no obstacle sensing.
pub fn hsi() -> HsiInfoPush {
    HsiInfoPush {
        up_distance: NO_OBSTACLE_DATA_MM,
        down_distance: NO_OBSTACLE_DATA_MM,
        up_enable: false,
        up_work: false,
        down_enable: false,
        down_work: false,
        around_distances: vec![NO_OBSTACLE_DATA_MM; AROUND_DIRECTIONS],
    }
}

/// Command latencies of one push period.
#[derive(Debug, Default)]
pub struct DelayMeter {
    sum: Duration,
    count: u32,
}

impl DelayMeter {
    pub fn record(&mut self, latency: Duration) {
        self.sum = self.sum.saturating_add(latency);
        self.count = self.count.saturating_add(1);
    }

    /// delay_info_push data for the period now ending; starts the next one.
    pub fn take(&mut self) -> DelayInfoPush {
        let ms = match self.count {
            0 => 0,
            n => {
                let mean_us = self.sum.as_micros() / u128::from(n);
                i64::try_from(mean_us.div_ceil(1000)).unwrap_or(i64::MAX)
            }
        };
        *self = DelayMeter::default();
        DelayInfoPush {
            sdr_cmd_delay: ms,
            liveview_delay_list: Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::{PayloadState, VehicleState};

    fn flying() -> Snapshot {
        Snapshot {
            state: Some(VehicleState {
                position_valid: 1,
                attitude_valid: 1,
                lat_deg: 47.1,
                lon_deg: 8.5,
                alt_msl_m: 512.0,
                vel_ned_mps: [1.0, -2.0, 0.5],
                yaw_rad: (-170f32).to_radians(),
                heading_deg: 10.0,
                ..Default::default()
            }),
            payload: Some(PayloadState {
                gimbal_valid: 1,
                gimbal_pitch_deg: -30.0,
                gimbal_roll_deg: 1.0,
                gimbal_yaw_deg: -20.0,
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    fn near(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-3
    }

    #[test]
    fn osd_maps_the_vehicle_state() {
        let o = osd(&flying()).expect("a position");
        assert!(near(o.attitude_head, -170.0), "{}", o.attitude_head);
        assert_eq!((o.latitude, o.longitude), (47.1, 8.5));
        assert_eq!(o.height, 512.0);
        assert_eq!(
            (o.speed_x, o.speed_y, o.speed_z),
            (1.0, -2.0, -0.5),
            "north, east, up"
        );
        assert_eq!((o.gimbal_pitch, o.gimbal_roll), (-30.0, 1.0));
        assert!(
            near(o.gimbal_yaw, 170.0),
            "−170 − 20 wraps to 170: {}",
            o.gimbal_yaw
        );
    }

    #[test]
    fn osd_falls_back_and_waits_for_a_position() {
        let mut s = flying();
        s.state.as_mut().unwrap().attitude_valid = 0;
        s.payload = None;
        let o = osd(&s).unwrap();
        assert!(near(o.attitude_head, 10.0), "heading over ground");
        let v = s.state.as_mut().unwrap();
        v.alt_ellipsoid_valid = 1;
        v.geoid_undulation_m = 19.5;
        assert_eq!(osd(&s).unwrap().height, 531.5, "ellipsoid height");
        assert_eq!((o.gimbal_pitch, o.gimbal_yaw), (0.0, 0.0), "no gimbal");
        s.state.as_mut().unwrap().position_valid = 0;
        assert!(osd(&s).is_none());
        assert!(osd(&Snapshot::default()).is_none());
    }

    #[test]
    fn hsi_says_no_sensors() {
        let h = hsi();
        assert!(!h.up_enable && !h.up_work && !h.down_enable && !h.down_work);
        assert_eq!(h.around_distances.len(), 360);
        assert!(h.around_distances.iter().all(|d| *d == NO_OBSTACLE_DATA_MM));
    }

    #[test]
    fn delay_is_the_mean_of_the_period_and_zero_without_samples() {
        let mut m = DelayMeter::default();
        assert_eq!(m.take().sdr_cmd_delay, 0);
        m.record(Duration::from_micros(1_500));
        m.record(Duration::from_micros(4_500));
        let d = m.take();
        assert_eq!(d.sdr_cmd_delay, 3);
        assert!(d.liveview_delay_list.is_empty());
        m.record(Duration::from_micros(10));
        assert_eq!(m.take().sdr_cmd_delay, 1, "measured is never 0");
        assert_eq!(m.take().sdr_cmd_delay, 0, "a new period");
    }

    #[test]
    fn angles_wrap() {
        assert_eq!(wrap_deg(190.0), -170.0);
        assert_eq!(wrap_deg(-180.0), -180.0);
        assert_eq!(wrap_deg(360.0), 0.0);
        assert_eq!(wrap_deg(f64::NAN), 0.0);
    }
}
