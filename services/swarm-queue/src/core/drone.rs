//! One drone's queue state and what is known of its vehicle.

use std::collections::VecDeque;
use std::sync::Arc;

use skymesh_ipc_types::{
    drone_flags, DroneState, FlightMode, SwarmCommand, SwarmCommandKind, SwarmDrone, VehicleState,
    VehicleStatus,
};

use crate::anim::{Animation, Keyframe};
use crate::config::{DroneConfig, Settings};
use crate::site::{enu_quaternion, yaw_of_heading, SiteFrame};

/// Below this height above home a descending drone is "landing slow".
pub const LANDING_SLOW_BELOW_M: f32 = 2.0;
/// A landed drone moves vertically slower than this, m/s.
const LANDED_MAX_VZ_MPS: f32 = 0.3;

/// An axis-aligned box in the site frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl Aabb {
    pub fn contains(&self, p: [f32; 3]) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }

    pub fn clamp(&self, p: [f32; 3]) -> [f32; 3] {
        [0, 1, 2].map(|i| p[i].clamp(self.min[i], self.max[i]))
    }

    /// The overlap of two boxes, `None` if they do not overlap.
    pub fn intersect(&self, other: &Aabb) -> Option<Aabb> {
        let min = [0, 1, 2].map(|i| self.min[i].max(other.min[i]));
        let max = [0, 1, 2].map(|i| self.max[i].min(other.max[i]));
        (0..3)
            .all(|i| min[i] <= max[i])
            .then_some(Aabb { min, max })
    }
}

/// The bounding box and the geofence do not overlap: no position is allowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("bounding box and geofence do not overlap")]
pub struct NoOverlap;

/// A command waiting in a queue (or saved): as received (after clamping), with the
/// animation it plays resolved on receipt.
#[derive(Debug, Clone)]
pub struct Queued {
    pub cmd: SwarmCommand,
    pub kind: SwarmCommandKind,
    pub anim: Option<Arc<Animation>>,
}

/// What a running command is doing.
#[derive(Debug, Clone)]
pub enum Exec {
    /// `GO_EXTERNAL`: GUIDED → arm → takeoff, each step after the previous one's
    /// acceptance, then climb.
    Takeoff {
        step: TakeoffStep,
        target: [f32; 3],
    },
    /// `WAYPOINT`, `SET_MANUAL_TARGET`, and (never finishing) `WAYPOINT_FOLLOW`.
    Waypoint {
        target: [f32; 3],
        yaw: f32,
        speed: f32,
        follow: bool,
        /// The target changed since it was last sent.
        dirty: bool,
    },
    /// `GO_HOME`: fly to home at the current height, then land.
    GoHome {
        target: [f32; 3],
        /// The position target has been sent.
        sent: bool,
        landing: bool,
    },
    /// `GO_HOME_AT_POSITION`.
    Land {
        target: [f32; 3],
    },
    Pause {
        until_ns: u64,
    },
    /// `COLOR` and `COLOR_GRADIENT`.
    Color {
        from: [f32; 3],
        to: [f32; 3],
        start_ns: u64,
        dur_ns: u64,
    },
    Anim(AnimRun),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TakeoffStep {
    Mode,
    Arm,
    Takeoff,
    Climb,
}

/// A playing animation.
#[derive(Debug, Clone)]
pub struct AnimRun {
    pub anim: Arc<Animation>,
    /// Times of the first and last frame played.
    pub t0: f64,
    pub t1: f64,
    /// Current animation time (file time axis).
    pub time: f64,
    pub last_ns: u64,
    pub looping: bool,
    /// `ANIM_CANCEL_LOOP`: finish at the end of the current loop.
    pub cancel: bool,
    pub speed: f32,
    pub use_pos: bool,
    pub use_color: bool,
    pub frame: usize,
    /// The last sampled point (offset applied), site frame.
    pub point: Keyframe,
}

/// The command a drone is executing.
#[derive(Debug, Clone)]
pub struct Running {
    pub q: Queued,
    /// Owner token of the vehicle commands it sends.
    pub token: u64,
    pub started_ns: u64,
    pub deadline_ns: Option<u64>,
    pub exec: Exec,
    /// `command_id` whose acceptance must come before the next step (GUIDED before
    /// a position target; each step of a takeoff).
    pub awaiting: Option<u32>,
}

/// Who waits for a vehicle command's acknowledgement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Owner {
    /// The running command with this token.
    Current(u64),
    /// An immediate command answered by the vehicle (`SideOp` with this token).
    Side(u64),
    /// Nobody (brake after a halt, LED-free side effects).
    Nobody,
}

#[derive(Debug, Clone, Copy)]
pub struct Pending {
    pub command_id: u32,
    pub owner: Owner,
}

/// An immediate command whose reply waits for the vehicle's acknowledgement.
#[derive(Debug, Clone)]
pub struct SideOp {
    pub token: u64,
    pub cmd: SwarmCommand,
    pub deadline_ns: u64,
}

/// A geofence sent to the arbiter whose `GeofenceUpdated` / `GeofenceInvalid` event
/// (matched by `request_id`) the command's reply waits for.
#[derive(Debug, Clone)]
pub struct FenceRequest {
    pub request_id: u32,
    pub cmd: SwarmCommand,
    /// The box the drone's fence becomes once the arbiter took it.
    pub fence: Aabb,
    pub deadline_ns: u64,
}

/// The newest vehicle state, converted once on receipt.
#[derive(Debug, Clone, Copy)]
pub struct Pose {
    /// Site frame position of the vehicle (without the calibration offset).
    pub site: [f32; 3],
    pub alt_rel: f32,
    /// Home altitude above mean sea level (`alt_msl − alt_rel`).
    pub home_alt_msl: f64,
    /// Velocity down, m/s.
    pub vd: f32,
    /// CCW degrees from east.
    pub yaw: f32,
    /// x, y, z, w; body FLU → site ENU.
    pub quat: [f32; 4],
    pub position_valid: bool,
    pub stamp_ns: u64,
}

impl Pose {
    pub fn from_state(site: &SiteFrame, s: &VehicleState) -> Pose {
        let [x, y] = site.to_site_xy(s.lat_deg, s.lon_deg);
        let yaw = if s.attitude_valid == 1 && s.yaw_rad.is_finite() {
            yaw_of_heading(s.yaw_rad.to_degrees())
        } else if s.heading_deg.is_finite() {
            yaw_of_heading(s.heading_deg)
        } else {
            0.0
        };
        let quat = if s.attitude_valid == 1 {
            enu_quaternion(s.attitude_q)
        } else {
            let h = (yaw.to_radians() / 2.0).sin_cos();
            [0.0, 0.0, h.0, h.1]
        };
        let finite = s.lat_deg.is_finite()
            && s.lon_deg.is_finite()
            && s.alt_msl_m.is_finite()
            && s.alt_rel_m.is_finite();
        Pose {
            site: [
                x as f32,
                y as f32,
                site.z_of_msl(f64::from(s.alt_msl_m)) as f32,
            ],
            alt_rel: s.alt_rel_m,
            home_alt_msl: f64::from(s.alt_msl_m) - f64::from(s.alt_rel_m),
            vd: if s.vel_ned_mps[2].is_finite() {
                s.vel_ned_mps[2]
            } else {
                0.0
            },
            yaw,
            quat,
            position_valid: s.position_valid == 1 && finite,
            stamp_ns: s.position_stamp_ns,
        }
    }

    /// On the ground: low above home and not moving vertically.
    pub fn landed(&self, landed_alt_m: f32) -> bool {
        self.alt_rel <= landed_alt_m && self.vd.abs() < LANDED_MAX_VZ_MPS
    }
}

/// The target a streamed position command was last sent for.
#[derive(Debug, Clone, Copy, Default)]
pub struct Stream {
    pub last_ns: Option<u64>,
    pub last_speed: Option<f32>,
}

/// One drone.
#[derive(Debug)]
pub struct Drone {
    pub id: u16,
    pub vehicle_id: u8,
    pub setup_home: Option<[f32; 3]>,
    pub active: bool,
    /// This queue's own emergency stop is in force at the arbiter (its engagement
    /// was accepted, and neither released nor cleared since).
    pub emergency: bool,
    pub current: Option<Running>,
    pub queue: VecDeque<Queued>,
    pub saved: Option<Queued>,
    pub color: [f32; 3],
    pub text: String,
    pub home: Option<[f32; 3]>,
    pub home_yaw: f32,
    pub bbox: Option<Aabb>,
    pub fence: Option<Aabb>,
    pub relative_rotation: f32,
    pub group: i32,
    pub ctrl_mode: i32,
    pub manual_color: bool,
    pub anim_intensity: f32,
    pub anim_offset: [f32; 3],
    pub calibration: [f32; 3],
    pub clock_timeout_ms: i32,
    pub tracking_frame: Option<i32>,
    pub pose: Option<Pose>,
    pub status: Option<VehicleStatus>,
    pub status_rx_ns: u64,
    /// The autopilot's home as first reported, site frame (the default "setup" home).
    pub autopilot_home: Option<[f32; 3]>,
    pub pending: VecDeque<Pending>,
    pub side: Vec<SideOp>,
    /// Geofences waiting for the arbiter's decision.
    pub fence_requests: Vec<FenceRequest>,
    pub stream: Stream,
    /// The token of the command whose `GoTo` / `Takeoff` is the arbiter's position
    /// target for this vehicle (the last one the queue sent, not ended since by
    /// another motion command of the queue: the arbiter's own bookkeeping).
    pub target_token: Option<u64>,
    /// When the queue last sent this vehicle a command of the flight domain (each
    /// one the arbiter admits refreshes the queue's flight authority).
    pub flight_sent_ns: Option<u64>,
}

/// Acknowledgements remembered per drone; older ones are forgotten (their commands
/// then end by their own timeouts).
pub const MAX_PENDING: usize = 64;

impl Drone {
    pub fn new(c: &DroneConfig) -> Drone {
        Drone {
            id: c.id,
            vehicle_id: c.vehicle_id,
            setup_home: c.home,
            active: true,
            emergency: false,
            current: None,
            queue: VecDeque::new(),
            saved: None,
            color: [0.0; 3],
            text: String::new(),
            home: None,
            home_yaw: 0.0,
            bbox: None,
            fence: None,
            relative_rotation: 0.0,
            group: 0,
            ctrl_mode: 0,
            manual_color: false,
            anim_intensity: 1.0,
            anim_offset: [0.0; 3],
            calibration: [0.0; 3],
            clock_timeout_ms: 0,
            tracking_frame: None,
            pose: None,
            status: None,
            status_rx_ns: 0,
            autopilot_home: None,
            pending: VecDeque::new(),
            side: Vec::new(),
            fence_requests: Vec::new(),
            stream: Stream::default(),
            target_token: None,
            flight_sent_ns: None,
        }
    }

    /// The pose if its position is valid and fresh.
    pub fn fresh_pose(&self, now_ns: u64, cfg: &Settings) -> Option<&Pose> {
        self.pose.as_ref().filter(|p| {
            p.position_valid
                && now_ns.saturating_sub(p.stamp_ns) <= cfg.pose_timeout.as_nanos() as u64
        })
    }

    /// Tracked position as GroundControl sees it: vehicle + calibration offset.
    pub fn tracking(&self) -> Option<[f32; 3]> {
        self.pose
            .as_ref()
            .map(|p| [0, 1, 2].map(|i| p.site[i] + self.calibration[i]))
    }

    pub fn armed(&self) -> Option<bool> {
        self.status.as_ref().map(VehicleStatus::is_armed)
    }

    pub fn link_down(&self, now_ns: u64, cfg: &Settings) -> bool {
        match &self.status {
            None => true,
            Some(s) => {
                !s.is_link_up()
                    || now_ns.saturating_sub(self.status_rx_ns) > cfg.link_timeout.as_nanos() as u64
            }
        }
    }

    pub fn idle(&self) -> bool {
        self.current.is_none() && self.queue.is_empty()
    }

    /// The queue's own box: bounding box ∩ geofence.
    pub fn limits(&self) -> Result<Option<Aabb>, NoOverlap> {
        match (&self.bbox, &self.fence) {
            (None, None) => Ok(None),
            (Some(b), None) | (None, Some(b)) => Ok(Some(*b)),
            (Some(a), Some(b)) => a.intersect(b).map(Some).ok_or(NoOverlap),
        }
    }

    fn landing(&self) -> bool {
        match self.current.as_ref().map(|r| &r.exec) {
            Some(Exec::Land { .. }) => true,
            Some(Exec::GoHome { landing, .. }) => *landing,
            _ => self
                .status
                .as_ref()
                .is_some_and(|s| s.flight_mode() == FlightMode::Land),
        }
    }

    /// GroundControl's `DroneState` (table in the crate docs).
    pub fn drone_state(&self, cfg: &Settings) -> DroneState {
        let (Some(pose), Some(status)) = (&self.pose, &self.status) else {
            return DroneState::None;
        };
        let taking_off = self
            .current
            .as_ref()
            .is_some_and(|r| r.q.kind == SwarmCommandKind::ExtGoExternal);
        if !status.is_armed() {
            return if taking_off {
                DroneState::TakeoffWait
            } else {
                DroneState::OnGround
            };
        }
        if pose.landed(cfg.landed_alt_m) {
            return if taking_off {
                DroneState::TakeoffMotorsOn
            } else {
                DroneState::LandingMotorsOff
            };
        }
        if taking_off {
            DroneState::Takeoff
        } else if self.landing() {
            if pose.alt_rel > LANDING_SLOW_BELOW_M {
                DroneState::LandingFast
            } else {
                DroneState::LandingSlow
            }
        } else {
            DroneState::FollowTarget
        }
    }

    /// The current command's target (site frame, as GroundControl sees it) and yaw.
    fn target(&self) -> Option<([f32; 3], Option<f32>)> {
        let r = self.current.as_ref()?;
        match &r.exec {
            Exec::Takeoff { target, .. } | Exec::GoHome { target, .. } | Exec::Land { target } => {
                Some((*target, None))
            }
            Exec::Waypoint { target, yaw, .. } => Some((*target, Some(*yaw))),
            Exec::Anim(a) if a.use_pos => Some((a.point.pos, Some(a.point.yaw_deg))),
            _ => None,
        }
    }

    /// This drone's entry of `SwarmState`.
    pub fn snapshot(&self, now_ns: u64, cfg: &Settings) -> SwarmDrone {
        let mut flags = 0;
        if self.idle() {
            flags |= drone_flags::IDLE;
        }
        if self.active {
            flags |= drone_flags::ACTIVE;
        }
        if self.fresh_pose(now_ns, cfg).is_some() {
            flags |= drone_flags::POSE_VALID;
        }
        if self.saved.is_some() {
            flags |= drone_flags::HAS_SAVED;
        }
        if self.emergency {
            flags |= drone_flags::EMERGENCY;
        }
        if self.link_down(now_ns, cfg) {
            flags |= drone_flags::LINK_DOWN;
        }
        let tracking = self.tracking().unwrap_or([0.0; 3]);
        let (yaw, quat) = self
            .pose
            .as_ref()
            .map_or((0.0, [0.0, 0.0, 0.0, 1.0]), |p| (p.yaw, p.quat));
        let (target, target_yaw) = match self.target() {
            Some((t, y)) => (t, y.unwrap_or(yaw)),
            None => (tracking, yaw),
        };
        let anim_frame = match self.current.as_ref().map(|r| &r.exec) {
            Some(Exec::Anim(a)) => a.frame as u32,
            _ => 0,
        };
        SwarmDrone {
            drone: self.id,
            vehicle_id: self.vehicle_id,
            drone_state: self.drone_state(cfg).to_wire(),
            flags,
            current: self.current.as_ref().map_or(0, |r| r.q.kind.to_wire()),
            reserved: 0,
            queue_depth: self.queue.len().min(usize::from(u16::MAX)) as u16,
            anim_frame,
            tracking,
            tracking_yaw_deg: yaw,
            quaternion: quat,
            target,
            target_yaw_deg: target_yaw,
            color: self.color,
            relative_rotation_deg: self.relative_rotation,
        }
    }
}
