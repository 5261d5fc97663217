//! [`CameraDemand`]: a frame reader's word to the camera that it reads a stream's
//! frames now, so an idle camera sleeps until a word comes instead of looking for
//! subscribers at its frame rate.
//!
//! Topic: [`crate::topics::camera_demand`] (one per stream, latest value per
//! publisher).

use iceoryx2::prelude::ZeroCopySend;

use crate::header::SampleHeader;

/// A reader's word that it reads the frames of the topic's stream now: the vision
/// pipeline says so when it starts reading (its output is used) and renews it every
/// second while it reads, and says `wanted = 0` when it stops. The camera keeps each
/// publisher's (header `service`, `instance`) newest word for
/// [`CAMERA_DEMAND_LEASE_NS`], so a dead reader's word lapses; while no word says
/// `wanted` (and the frame topic has no subscriber, looked at once a second, and the
/// config does not say `always_on`) it makes no frames. A word that says `wanted`
/// wakes an idle camera at once: its next frame is made when the word arrives.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.CameraDemand.v1")]
#[repr(C)]
pub struct CameraDemand {
    pub header: SampleHeader,
    /// 1: the frames are read now; 0: not any more.
    pub wanted: u8,
    pub reserved: [u8; 7],
}
crate::assert_layout!(CameraDemand, size = 24 + 8, align = 8);

/// How long a [`CameraDemand`] that says `wanted` holds without being renewed.
pub const CAMERA_DEMAND_LEASE_NS: u64 = 3_000_000_000;

crate::impl_sample!(CameraDemand);
