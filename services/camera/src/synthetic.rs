//! The synthetic source: follows the vehicle's pose and gimbal, and renders each
//! frame of the scene straight into the frame's shared-memory slice.
//!
//! The camera hangs on a stabilised gimbal at the vehicle's position: its yaw is the
//! vehicle's yaw plus the gimbal's yaw relative to the nose, its pitch and roll are
//! the gimbal's (earth-referenced), or the configured mount's while the gimbal's
//! attitude is not valid. Vehicle roll and pitch do not move the picture.
//!
//! The frame header carries the pose the frame was rendered from: the vehicle's
//! latitude, longitude and altitude MSL, and in `pose.attitude_q` the **camera mount
//! → NED** quaternion `[w, x, y, z]` (mount frame: x along the optical axis, y image
//! right, z image down; see [`crate::render`]). Intrinsics are exact (no distortion).

use skymesh_ipc_types::{
    CameraIntrinsics, CapturePose, FrameHeader, LensModel, PayloadState, SceneTruth, TargetTruth,
    VehicleState, SCENE_MAX_TARGETS,
};

use crate::config::Settings;
use crate::render::{
    mount_attitude, render_nv12, render_rgb24, CameraPose, Lens, PlacedTarget, Scene, Shape,
};
use crate::scene::{Origin, TargetState};

/// Where the vehicle is (the part of `VehicleState` the camera uses).
#[derive(Debug, Clone, Copy, PartialEq)]
struct VehiclePose {
    lat_deg: f64,
    lon_deg: f64,
    alt_msl_m: f64,
    yaw_deg: f64,
}

/// The gimbal's earth-referenced pitch and roll and its yaw relative to the nose.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Gimbal {
    pitch_deg: f64,
    roll_deg: f64,
    yaw_deg: f64,
}

/// The scene and what the camera knows of the vehicle.
#[derive(Debug)]
pub struct Synthetic {
    settings: Settings,
    origin: Option<Origin>,
    vehicle: Option<VehiclePose>,
    gimbal: Option<Gimbal>,
}

/// Why no frame can be rendered now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NoPose;

impl Synthetic {
    pub fn new(settings: Settings) -> Self {
        Synthetic {
            origin: settings.synthetic.origin,
            settings,
            vehicle: None,
            gimbal: None,
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
        if v.position_valid == 0 || v.attitude_valid == 0 {
            return;
        }
        let pose = VehiclePose {
            lat_deg: v.lat_deg,
            lon_deg: v.lon_deg,
            alt_msl_m: f64::from(v.alt_msl_m),
            yaw_deg: f64::from(v.yaw_rad).to_degrees(),
        };
        let alt_rel = f64::from(v.alt_rel_m);
        let ok = [
            pose.lat_deg,
            pose.lon_deg,
            pose.alt_msl_m,
            pose.yaw_deg,
            alt_rel,
        ]
        .iter()
        .all(|x| x.is_finite())
            && pose.lat_deg.abs() <= 85.0
            && pose.lon_deg.abs() <= 180.0;
        if !ok {
            return;
        }
        if self.origin.is_none() {
            self.origin = Some(Origin {
                lat_deg: pose.lat_deg,
                lon_deg: pose.lon_deg,
                ground_alt_msl_m: pose.alt_msl_m - alt_rel,
            });
        }
        self.vehicle = Some(pose);
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
        self.gimbal =
            (self.settings.mount.use_gimbal && p.is_gimbal_valid() && finite).then_some(g);
    }

    /// The camera's pose in the scene and the header's capture pose.
    /// (The vehicle's heading, degrees, is the fourth element.)
    pub fn pose(&self) -> Result<(Origin, CameraPose, CapturePose, f32), NoPose> {
        let origin = self.origin.ok_or(NoPose)?;
        let v = match self.vehicle {
            Some(v) => v,
            None if self.settings.synthetic.origin.is_some() => VehiclePose {
                lat_deg: origin.lat_deg,
                lon_deg: origin.lon_deg,
                alt_msl_m: origin.ground_alt_msl_m + self.settings.synthetic.standby_height_m,
                yaw_deg: 0.0,
            },
            None => return Err(NoPose),
        };
        let m = self.settings.mount;
        let g = self.gimbal.unwrap_or(Gimbal {
            pitch_deg: m.pitch_deg,
            roll_deg: 0.0,
            yaw_deg: m.yaw_deg,
        });
        let attitude = mount_attitude(v.yaw_deg + g.yaw_deg, g.pitch_deg, g.roll_deg);
        let (n, e) = origin.to_ne(v.lat_deg, v.lon_deg);
        let cam = CameraPose {
            ned: nalgebra::Vector3::new(n, e, -(v.alt_msl_m - origin.ground_alt_msl_m)),
            attitude,
        };
        let q = attitude.quaternion();
        let capture = CapturePose {
            lat_deg: v.lat_deg,
            lon_deg: v.lon_deg,
            attitude_q: [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
            alt_m: v.alt_msl_m as f32,
            valid: 1,
            reserved: [0; 3],
        };
        Ok((origin, cam, capture, v.yaw_deg.rem_euclid(360.0) as f32))
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
        header.intrinsics = CameraIntrinsics {
            fx: k.fx as f32,
            fy: k.fy as f32,
            cx: k.cx as f32,
            cy: k.cy as f32,
            k: [0.0; 4],
            lens_model: match k.lens {
                Lens::Pinhole => LensModel::Pinhole,
                Lens::Fisheye => LensModel::Fisheye,
            }
            .to_wire(),
            valid: 1,
            reserved: [0; 2],
        };
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
