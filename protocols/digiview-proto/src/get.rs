//! What a GET frame asks for.
//!
//! FACTS.md: a GET carries the stream name in `data[0..8]` and the camera id in
//! `data[8]` (255 = none), whatever the parameter type — including
//! SINGLE_TARGET_TRACKING, whose SET layout has the stream at offset 1. DETECTED_ROI
//! is the exception: its GET reads only `data[0]`, the index ([`RoiSelector`]).

use crate::fixed::{FixedName, StreamName};
use crate::frame::ParamType;
use crate::validate::{PayloadError, Problem};
use crate::DATA_LEN;

/// `data[8]` of a GET that names no camera.
pub const CAM_NONE: u8 = 255;
/// DETECTED_ROI index: every detection visible in the output overlay.
pub const ROI_ALL_VISIBLE: u8 = 254;
/// DETECTED_ROI index: every known detection.
pub const ROI_ALL_KNOWN: u8 = 255;

/// The stream and camera a GET is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GetRequest {
    pub stream: StreamName,
    /// `None` on the wire is [`CAM_NONE`].
    pub cam: Option<u8>,
}

impl GetRequest {
    pub fn decode(param_type: ParamType, data: &[u8; DATA_LEN]) -> Result<Self, PayloadError> {
        let stream = FixedName::from_wire(&data[0..8]).map_err(|e| PayloadError {
            param: param_type,
            field: "stream",
            problem: Problem::Name(e),
        })?;
        let cam = (data[8] != CAM_NONE).then_some(data[8]);
        Ok(GetRequest { stream, cam })
    }

    pub fn encode(&self) -> [u8; DATA_LEN] {
        let mut data = [0u8; DATA_LEN];
        data[0..8].copy_from_slice(&self.stream.wire());
        data[8] = self.cam.unwrap_or(CAM_NONE);
        data
    }
}

/// Which detections a DETECTED_ROI GET asks for; one CURRENT reply per detection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RoiSelector {
    /// One detection, index 0–253.
    One(u8),
    /// Index 254: every detection visible in the output overlay.
    AllVisible,
    /// Index 255: every known detection.
    AllKnown,
}

impl RoiSelector {
    pub fn decode(data: &[u8; DATA_LEN]) -> Self {
        Self::from_index(data[0])
    }

    pub fn from_index(index: u8) -> Self {
        match index {
            ROI_ALL_VISIBLE => RoiSelector::AllVisible,
            ROI_ALL_KNOWN => RoiSelector::AllKnown,
            i => RoiSelector::One(i),
        }
    }

    pub fn index(self) -> u8 {
        match self {
            RoiSelector::One(i) => i,
            RoiSelector::AllVisible => ROI_ALL_VISIBLE,
            RoiSelector::AllKnown => ROI_ALL_KNOWN,
        }
    }

    pub fn encode(self) -> [u8; DATA_LEN] {
        let mut data = [0u8; DATA_LEN];
        data[0] = self.index();
        data
    }
}
