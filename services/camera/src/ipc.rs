//! Every bus call of the camera service.
//!
//! | topic | direction | type |
//! |---|---|---|
//! | `skymesh/vehicle/{id}/state` | subscribe | `VehicleState` (the pose frames are rendered from) |
//! | `skymesh/vehicle/{id}/payload` | subscribe | `PayloadState` (the gimbal's attitude) |
//! | `skymesh/camera/{stream}/demand` | subscribe | `CameraDemand` (readers' word that they read the frames; wakes the idle camera) |
//! | `skymesh/camera/{stream}/frames` | publish | frames: `FrameHeader` + pixels, written in place |
//! | `skymesh/camera/{stream}/truth` | publish | `SceneTruth` (one per synthetic frame; not opened for a file source, which has no truth) |

use anyhow::Context as _;
use skymesh_ipc_types::{
    topics, CameraDemand, FrameHeader, PayloadState, SceneTruth, VehicleState,
};
use skymesh_runtime::{Bus, FrameError, FramePublisher, IpcError, Publisher, Subscriber};

use crate::config::{Settings, Source};

#[derive(Debug)]
pub(crate) struct Ports {
    vehicle: Subscriber<VehicleState>,
    payload: Subscriber<PayloadState>,
    /// Readers' demand words, awaited while idle.
    pub demand: Subscriber<CameraDemand>,
    frames: FramePublisher,
    truth: Option<Publisher<SceneTruth>>,
}

impl Ports {
    pub fn open(bus: &Bus, s: &Settings) -> anyhow::Result<Ports> {
        Ok(Ports {
            vehicle: bus
                .subscriber(&topics::vehicle_state(s.vehicle_id))
                .context("opening the vehicle state topic")?,
            payload: bus
                .subscriber(&topics::vehicle_payload(s.vehicle_id))
                .context("opening the payload state topic")?,
            demand: bus
                .subscriber(&topics::camera_demand(&s.stream))
                .context("opening the camera demand topic")?,
            frames: bus
                .frame_publisher(&topics::camera_frames(&s.stream), s.frame_len())
                .context("opening the camera frame topic")?,
            truth: match s.source {
                Source::Synthetic => Some(
                    bus.publisher(&topics::camera_truth(&s.stream))
                        .context("opening the camera truth topic")?,
                ),
                Source::Y4m(_) => None,
            },
        })
    }

    /// How many subscribers the frame topic has now (the vision pipeline only while
    /// its output is used, which also sends a word; tools, tests).
    pub fn readers(&self) -> usize {
        self.frames.subscribers()
    }

    /// The newest vehicle state and payload state received since the last call.
    pub fn inputs(&self) -> Result<(Option<VehicleState>, Option<PayloadState>), IpcError> {
        Ok((self.vehicle.latest()?, self.payload.latest()?))
    }

    pub fn frame(
        &mut self,
        len: usize,
        fill: impl FnOnce(&mut FrameHeader, &mut [u8]),
    ) -> Result<u64, FrameError> {
        self.frames.publish_with(len, fill)
    }

    /// Publishes the synthetic scene's truth (nothing for other sources).
    pub fn truth(&mut self, truth: SceneTruth) -> Result<(), IpcError> {
        match &mut self.truth {
            Some(p) => p.publish(truth).map(|_| ()),
            None => Ok(()),
        }
    }
}
