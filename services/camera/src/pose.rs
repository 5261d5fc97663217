//! What the camera knows of where it is: the vehicle's position and heading
//! (`VehicleState`) and the gimbal's attitude (`PayloadState`) or the configured
//! mount. Shared by every source; the frame header's `pose` comes from here.
//!
//! The camera hangs on a stabilised gimbal at the vehicle's position: its yaw is the
//! vehicle's yaw plus the gimbal's yaw relative to the nose, its pitch and roll are
//! the gimbal's (earth-referenced), or the configured mount's while the gimbal's
//! attitude is not valid. Vehicle roll and pitch do not move the picture.

use nalgebra::UnitQuaternion;
use skymesh_ipc_types::{CapturePose, PayloadState, VehicleState};

use crate::config::Mount;
use crate::render::mount_attitude;

/// Where the vehicle is (the part of `VehicleState` the camera uses).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehiclePose {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_msl_m: f64,
    pub yaw_deg: f64,
    /// Altitude above home, m (the synthetic scene puts its ground at home).
    pub alt_rel_m: f64,
}

/// The gimbal's earth-referenced pitch and roll and its yaw relative to the nose.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Gimbal {
    pitch_deg: f64,
    roll_deg: f64,
    yaw_deg: f64,
}

/// The newest vehicle pose and gimbal attitude.
#[derive(Debug, Clone)]
pub struct PoseTracker {
    mount: Mount,
    vehicle: Option<VehiclePose>,
    gimbal: Option<Gimbal>,
}

impl PoseTracker {
    pub fn new(mount: Mount) -> Self {
        PoseTracker {
            mount,
            vehicle: None,
            gimbal: None,
        }
    }

    /// Takes the newest vehicle state: ignored (returns `None`) until it has a
    /// position and an attitude, and if any field used is not finite.
    pub fn update_vehicle(&mut self, v: &VehicleState) -> Option<VehiclePose> {
        if v.position_valid == 0 || v.attitude_valid == 0 {
            return None;
        }
        let pose = VehiclePose {
            lat_deg: v.lat_deg,
            lon_deg: v.lon_deg,
            alt_msl_m: f64::from(v.alt_msl_m),
            yaw_deg: f64::from(v.yaw_rad).to_degrees(),
            alt_rel_m: f64::from(v.alt_rel_m),
        };
        let ok = [
            pose.lat_deg,
            pose.lon_deg,
            pose.alt_msl_m,
            pose.yaw_deg,
            pose.alt_rel_m,
        ]
        .iter()
        .all(|x| x.is_finite())
            && pose.lat_deg.abs() <= 85.0
            && pose.lon_deg.abs() <= 180.0;
        if !ok {
            return None;
        }
        self.vehicle = Some(pose);
        Some(pose)
    }

    /// Takes the newest payload state: the gimbal's attitude while it is valid.
    pub fn update_payload(&mut self, p: &PayloadState) {
        let g = Gimbal {
            pitch_deg: f64::from(p.gimbal_pitch_deg),
            roll_deg: f64::from(p.gimbal_roll_deg),
            yaw_deg: f64::from(p.gimbal_yaw_deg),
        };
        let finite = [g.pitch_deg, g.roll_deg, g.yaw_deg]
            .iter()
            .all(|x| x.is_finite());
        self.gimbal = (self.mount.use_gimbal && p.is_gimbal_valid() && finite).then_some(g);
    }

    /// The newest valid vehicle pose.
    pub fn vehicle(&self) -> Option<VehiclePose> {
        self.vehicle
    }

    /// The camera's attitude (mount → NED), the header's capture pose and the
    /// vehicle's heading (degrees, 0..360) for the vehicle at `v`.
    pub fn capture(&self, v: &VehiclePose) -> (UnitQuaternion<f64>, CapturePose, f32) {
        let m = self.mount;
        let g = self.gimbal.unwrap_or(Gimbal {
            pitch_deg: m.pitch_deg,
            roll_deg: 0.0,
            yaw_deg: m.yaw_deg,
        });
        let attitude = mount_attitude(v.yaw_deg + g.yaw_deg, g.pitch_deg, g.roll_deg);
        let q = attitude.quaternion();
        let capture = CapturePose {
            lat_deg: v.lat_deg,
            lon_deg: v.lon_deg,
            attitude_q: [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
            alt_m: v.alt_msl_m as f32,
            valid: 1,
            reserved: [0; 3],
        };
        (attitude, capture, v.yaw_deg.rem_euclid(360.0) as f32)
    }
}
