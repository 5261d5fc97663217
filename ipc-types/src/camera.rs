//! Ground truth of the camera's synthetic scene: where every simulated target really
//! is, published with every rendered frame so tests (and the vision pipeline's
//! evaluation) can compare detections and geolocation against it.
//!
//! Topic: [`crate::topics::camera_truth`].

use iceoryx2::prelude::ZeroCopySend;

use crate::header::SampleHeader;

/// The most targets a synthetic scene holds.
pub const SCENE_MAX_TARGETS: usize = 16;

/// One simulated target at the capture time of a frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct TargetTruth {
    /// WGS84 latitude of the target's centre, degrees.
    pub lat_deg: f64,
    /// WGS84 longitude of the target's centre, degrees.
    pub lon_deg: f64,
    /// Altitude of the target (the ground plane) above mean sea level, m.
    pub alt_msl_m: f32,
    /// Stable target id (from the camera's config).
    pub id: u32,
    /// Diameter (disc) or side (square), m.
    pub size_m: f32,
    /// Velocity north and east, m/s.
    pub vel_n_mps: f32,
    pub vel_e_mps: f32,
    /// Where the target's centre projects in the frame, pixels (valid if `in_view`).
    pub pixel_u: f32,
    pub pixel_v: f32,
    /// 0 disc, 1 square.
    pub shape: u8,
    /// 1 if the centre projects inside the frame (in front of the camera).
    pub in_view: u8,
    /// Colour, R G B.
    pub rgb: [u8; 3],
    pub reserved: [u8; 3],
}
crate::assert_layout!(TargetTruth, size = 56, align = 8);

/// The true positions of a synthetic scene's targets at one frame's capture.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.SceneTruth.v1")]
#[repr(C)]
pub struct SceneTruth {
    pub header: SampleHeader,
    pub vehicle_id: u8,
    /// Targets used in `targets` (the rest are zero).
    pub count: u8,
    pub reserved: [u8; 6],
    /// The `frame_seq` of the frame this truth belongs to.
    pub frame_seq: u64,
    /// The frame's `capture_mono_ns`.
    pub capture_mono_ns: u64,
    pub targets: [TargetTruth; SCENE_MAX_TARGETS],
}
crate::assert_layout!(
    SceneTruth,
    size = 24 + 8 + 16 + 56 * SCENE_MAX_TARGETS,
    align = 8
);

crate::impl_sample!(SceneTruth);

impl SceneTruth {
    /// The targets in use.
    pub fn targets(&self) -> &[TargetTruth] {
        &self.targets[..usize::from(self.count).min(SCENE_MAX_TARGETS)]
    }
}
