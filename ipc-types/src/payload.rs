//! What the vehicle's payload reports: gimbal attitude and the GoPro on it.
//!
//! Published by `autopilot-link` from MAVLink `GIMBAL_DEVICE_ATTITUDE_STATUS` (gimbal
//! protocol v2) and `GOPRO_HEARTBEAT` (the Solo gimbal's GoPro bridge). Fields whose
//! source has never been heard stay invalid; nothing is assumed.

use iceoryx2::prelude::ZeroCopySend;

use crate::header::SampleHeader;
use crate::wire_enum;

wire_enum! {
    /// `GOPRO_HEARTBEAT.status`, numbered as MAVLink's GOPRO_HEARTBEAT_STATUS and the
    /// Solo app's GOPRO_STATE status field.
    pub enum GoProStatus: u8 {
        /// No GoPro heartbeat heard (or none for 3 s).
        Disconnected = 0 => "disconnected",
        Incompatible = 1 => "incompatible",
        Connected = 2 => "connected",
        Fault = 3 => "error",
    }
}

/// Gimbal and camera state of one vehicle, on change and at 1 Hz.
///
/// Topic: [`crate::topics::vehicle_payload`] (latest value).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[type_name("skymesh.PayloadState.v1")]
#[repr(C)]
pub struct PayloadState {
    pub header: SampleHeader,
    pub vehicle_id: u8,
    /// 1 once a gimbal attitude has been received (and not older than 2 s).
    pub gimbal_valid: u8,
    /// [`GoProStatus`] as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::GoProStatus>")
    )]
    pub gopro_status: u8,
    /// `GOPRO_HEARTBEAT.capture_mode` (MAVLink GOPRO_CAPTURE_MODE: 0 video, 1 photo,
    /// 2 burst, 3 time lapse, 4 multi shot, 5 playback, 6 setup, 255 unknown).
    pub gopro_capture_mode: u8,
    /// 1 while the GoPro records (`GOPRO_FLAG_RECORDING`).
    pub gopro_recording: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: [u8; 3],
    /// Camera pitch, degrees, down negative (horizon 0, straight down −90).
    pub gimbal_pitch_deg: f32,
    pub gimbal_roll_deg: f32,
    /// Camera yaw relative to the vehicle's nose, degrees, clockwise positive.
    pub gimbal_yaw_deg: f32,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved2: u32,
    /// `CLOCK_MONOTONIC` ns of the last gimbal attitude (0 = never).
    pub gimbal_stamp_ns: u64,
    /// `CLOCK_MONOTONIC` ns of the last GoPro heartbeat (0 = never).
    pub gopro_stamp_ns: u64,
}
crate::assert_layout!(PayloadState, size = 24 + 8 + 16 + 16, align = 8);

impl PayloadState {
    pub fn gopro_status(&self) -> GoProStatus {
        GoProStatus::try_from(self.gopro_status).unwrap_or(GoProStatus::Disconnected)
    }

    pub fn is_gimbal_valid(&self) -> bool {
        self.gimbal_valid != 0
    }
}

crate::impl_sample!(PayloadState);
