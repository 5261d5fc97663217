//! The synthetic source: follows the vehicle's pose and gimbal, and renders each
//! frame of the scene straight into the frame's shared-memory slice.
//!
//! The camera's pose (vehicle position, gimbal or mount) comes from
//! [`crate::pose::PoseTracker`].
//!
//! The frame header carries the pose the frame was rendered from: the vehicle's
//! latitude, longitude and altitude MSL, and in `pose.attitude_q` the **camera mount
//! → NED** quaternion `[w, x, y, z]` (mount frame: x along the optical axis, y image
//! right, z image down; see [`crate::render`]). Intrinsics are exact (no distortion).

use skymesh_ipc_types::{
    CapturePose, FrameHeader, PayloadState, SceneTruth, TargetTruth, VehicleState,
    SCENE_MAX_TARGETS,
};

use crate::config::Settings;
use crate::pose::{PoseTracker, VehiclePose};
use crate::render::{render_nv12, render_rgb24, CameraPose, PlacedTarget, Scene, Shape};
use crate::scene::{Origin, TargetState};

/// The scene and what the camera knows of the vehicle.
#[derive(Debug)]
pub struct Synthetic {
    settings: Settings,
    origin: Option<Origin>,
    tracker: PoseTracker,
}

/// Why no frame can be rendered now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NoPose;

impl Synthetic {
    pub fn new(settings: Settings) -> Self {
        Synthetic {
            origin: settings.synthetic.origin,
            tracker: PoseTracker::new(settings.mount),
            settings,
        }
    }

    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// The scene origin (configured, or the first vehicle position).
    pub fn origin(&self) -> Option<Origin> {
        self.origin
    }

    /// Takes the newest vehicle state: ignored until it has a position and an
    /// attitude, and if any field used is not finite. The first one sets the scene
    /// origin when none is configured (ground at its altitude above home below it).
    pub fn update_vehicle(&mut self, v: &VehicleState) {
        let Some(pose) = self.tracker.update_vehicle(v) else {
            return;
        };
        if self.origin.is_none() {
            self.origin = Some(Origin {
                lat_deg: pose.lat_deg,
                lon_deg: pose.lon_deg,
                ground_alt_msl_m: pose.alt_msl_m - pose.alt_rel_m,
            });
        }
    }

    /// Takes the newest payload state: the gimbal's attitude while it is valid.
    pub fn update_payload(&mut self, p: &PayloadState) {
        self.tracker.update_payload(p);
    }

    /// The camera's pose in the scene and the header's capture pose.
    /// (The vehicle's heading, degrees, is the fourth element.)
    pub fn pose(&self) -> Result<(Origin, CameraPose, CapturePose, f32), NoPose> {
        let origin = self.origin.ok_or(NoPose)?;
        let v = match self.tracker.vehicle() {
            Some(v) => v,
            None if self.settings.synthetic.origin.is_some() => VehiclePose {
                lat_deg: origin.lat_deg,
                lon_deg: origin.lon_deg,
                alt_msl_m: origin.ground_alt_msl_m + self.settings.synthetic.standby_height_m,
                yaw_deg: 0.0,
                alt_rel_m: self.settings.synthetic.standby_height_m,
            },
            None => return Err(NoPose),
        };
        let (attitude, capture, heading_deg) = self.tracker.capture(&v);
        let (n, e) = origin.to_ne(v.lat_deg, v.lon_deg);
        let cam = CameraPose {
            ned: nalgebra::Vector3::new(n, e, -(v.alt_msl_m - origin.ground_alt_msl_m)),
            attitude,
        };
        Ok((origin, cam, capture, heading_deg))
    }

    /// The targets `t_s` seconds after the scene started.
    pub fn targets_at(&self, t_s: f64) -> Vec<TargetState> {
        self.settings
            .synthetic
            .targets
            .iter()
            .map(|t| t.at(t_s))
            .collect()
    }

    /// Renders one frame `t_s` seconds into the scene into `pixels` and fills
    /// `header` (geometry, intrinsics, pose, capture times, `frame_seq`); returns the
    /// scene's truth for that frame.
    pub fn render(
        &self,
        t_s: f64,
        frame: FrameStamp,
        header: &mut FrameHeader,
        pixels: &mut [u8],
    ) -> Result<SceneTruth, NoPose> {
        let (origin, cam, capture, heading_deg) = self.pose()?;
        let s = &self.settings;
        let states = self.targets_at(t_s);
        let placed: Vec<PlacedTarget> = states.iter().map(|t| t.placed).collect();
        let scene = Scene {
            targets: &placed,
            cell_m: s.synthetic.cell_m,
        };
        let k = &s.intrinsics;
        let stride = s.stride();
        let threads = s.synthetic.render_threads;
        match s.format {
            skymesh_ipc_types::PixelFormat::Rgb24 => render_rgb24(
                &scene,
                k,
                &cam,
                s.width,
                s.height,
                stride as usize,
                threads,
                pixels,
            ),
            skymesh_ipc_types::PixelFormat::Nv12 => render_nv12(
                &scene,
                k,
                &cam,
                s.width,
                s.height,
                stride as usize,
                threads,
                pixels,
            ),
        }
        header.set_geometry(s.format, s.width, s.height, stride);
        header.frame_seq = frame.seq;
        header.capture_mono_ns = frame.mono_ns;
        header.capture_unix_ns = frame.unix_ns;
        header.intrinsics = k.to_wire();
        header.pose = capture;
        header.vehicle_heading_deg = heading_deg;

        let mut truth = SceneTruth {
            vehicle_id: s.vehicle_id,
            frame_seq: frame.seq,
            capture_mono_ns: frame.mono_ns,
            ..SceneTruth::default()
        };
        let spec = &s.synthetic.targets;
        for ((slot, st), sp) in truth
            .targets
            .iter_mut()
            .zip(&states)
            .zip(spec)
            .take(SCENE_MAX_TARGETS)
        {
            let (lat, lon) = origin.to_latlon(st.placed.north, st.placed.east);
            let px = cam
                .project_ground(k, st.placed.north, st.placed.east)
                .filter(|(u, v)| {
                    (-0.5..f64::from(s.width) - 0.5).contains(u)
                        && (-0.5..f64::from(s.height) - 0.5).contains(v)
                });
            *slot = TargetTruth {
                lat_deg: lat,
                lon_deg: lon,
                alt_msl_m: origin.ground_alt_msl_m as f32,
                id: sp.id,
                size_m: sp.size_m as f32,
                vel_n_mps: st.vel_ne[0] as f32,
                vel_e_mps: st.vel_ne[1] as f32,
                pixel_u: px.map_or(0.0, |p| p.0 as f32),
                pixel_v: px.map_or(0.0, |p| p.1 as f32),
                shape: match sp.shape {
                    Shape::Disc => 0,
                    Shape::Square => 1,
                },
                in_view: u8::from(px.is_some()),
                rgb: sp.rgb,
                reserved: [0; 3],
            };
        }
        truth.count = states.len().min(SCENE_MAX_TARGETS) as u8;
        Ok(truth)
    }
}

/// A frame's sequence number and capture times.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameStamp {
    pub seq: u64,
    pub mono_ns: u64,
    pub unix_ns: u64,
}
