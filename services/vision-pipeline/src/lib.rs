//! skymesh vision pipeline (issue 8): the library behind `skymesh-vision`, the
//! service that turns camera frames into detections, tracks, virtual camera views
//! and captures, and owns every DigiView parameter.
//!
//! Module map:
//! - [`geometry`]: pure camera geometry on `nalgebra`: lens models (pixel ↔ ray),
//!   DigiView's normalised offsets, camera attitude, CAM_OFFSET angles and the
//!   ray–ground intersection behind DETECTED_ROI's latitude, longitude, altitude.
//! - [`detect`]: the detector models (MODEL) on a reduced work image.
//! - [`track`]: scoring and tracking (DETECTION), stable ids, overlay slots.
//! - [`stt`]: single-target tracking (SINGLE_TARGET_TRACKING).
//! - [`views`]: virtual cameras (CAM_TARGETING, CAM_OPTICS_AND_CONTROL, gimbal v2).
//! - [`layout`]: output layouts and detection overlays (VIDEO_OUTPUT).
//! - [`render`]: the output frame, remapped from the wide frame.
//! - [`capture`]: images and video to disk (CAPTURE).
//!
//! The service (`skymesh-vision`):
//! - [`config`]: `deploy/vision-pipeline.toml` → [`Settings`].
//! - [`params`]: the DigiView parameter state; every control → an effect or a refusal (pure).
//! - [`service`]: the loop: frames → detections, views, output frames, [`skymesh_ipc_types::VisionState`]; controls → replies.
//! - [`thermal`]: SYSTEM_STATUS temperature from a thermal zone.
//! - [`metrics`]: the service's series.
//! - `ipc`: every bus call.

pub mod capture;
pub mod config;
pub mod detect;
pub mod geometry;
mod ipc;
pub mod layout;
pub mod metrics;
pub mod params;
pub mod render;
pub mod service;
pub mod stt;
pub mod thermal;
pub mod track;
pub mod views;

pub use config::{RawConfig, Settings};
pub use service::run;
