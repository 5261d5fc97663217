//! skymesh vision pipeline (issue 8). A library for now: no binary, no service yet.
//!
//! Module map:
//! - [`geometry`]: pure camera geometry on `nalgebra`: the lens models of a frame's
//!   intrinsics (pixel ↔ unit ray), DigiView's normalised x/y offsets ↔ pixels, the
//!   camera's attitude (vehicle attitude × mount), CAM_OFFSET angles (relative to the
//!   camera, to the vehicle's heading, and global: true north / horizon) and the
//!   ray–ground intersection behind DETECTED_ROI's latitude, longitude, altitude and
//!   distance.
//!
//! Still to come (issue 8): detection, tracking and scoring, single-target tracking,
//! virtual cameras and their rendering, capture to disk, and the service around them.

pub mod geometry;
