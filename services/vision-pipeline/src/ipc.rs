//! Every bus call of the vision pipeline.
//!
//! | topic | direction | type |
//! |---|---|---|
//! | `skymesh/camera/{stream}/frames` | subscribe | frames: `FrameHeader` + pixels, read in place |
//! | `skymesh/vehicle/{id}/state` | subscribe | `VehicleState` (body attitude, height above home) |
//! | `skymesh/vision/control` | subscribe | `VisionControl` |
//! | `skymesh/vision/reply` | publish | `VisionReply` (one per control) |
//! | `skymesh/vision/state` | publish | `VisionState` (written in place) |
//! | `skymesh/vision/{stream}/output` | publish | output frames, rendered in place |

use anyhow::Context as _;
use skymesh_ipc_types::{
    topics, VehicleState, VisionControl, VisionReply, VisionState, MAX_FRAME_LEN,
};
use skymesh_runtime::{Bus, FramePublisher, FrameSubscriber, IpcError, Publisher, Subscriber};

use crate::config::Settings;

/// One stream's frame ports.
#[derive(Debug)]
pub struct StreamPorts {
    pub frames: FrameSubscriber,
    pub output: FramePublisher,
}

#[derive(Debug)]
pub struct Ports {
    pub streams: Vec<StreamPorts>,
    pub vehicle: Subscriber<VehicleState>,
    pub control: Subscriber<VisionControl>,
    pub sinks: Sinks,
}

/// The pipeline's non-frame outputs (apart from the frame ports, so a frame can be
/// read in place while they are written).
#[derive(Debug)]
pub struct Sinks {
    reply: Publisher<VisionReply>,
    state: Publisher<VisionState>,
}

impl Ports {
    pub fn open(bus: &Bus, s: &Settings) -> anyhow::Result<Ports> {
        let mut streams = Vec::with_capacity(s.streams.len());
        for st in &s.streams {
            streams.push(StreamPorts {
                frames: bus
                    .frame_subscriber(&topics::camera_frames(&st.name))
                    .with_context(|| format!("opening the camera frames of `{}`", st.name))?,
                // Sized for the largest output VIDEO_OUTPUT may ask for, so a SET
                // never needs a new publisher.
                output: bus
                    .frame_publisher(&topics::vision_output(&st.name), MAX_FRAME_LEN)
                    .with_context(|| format!("opening the vision output of `{}`", st.name))?,
            });
        }
        Ok(Ports {
            streams,
            vehicle: bus
                .subscriber(&topics::vehicle_state(s.vehicle_id))
                .context("opening the vehicle state topic")?,
            control: bus
                .subscriber(&topics::vision_control())
                .context("opening the vision control topic")?,
            sinks: Sinks {
                reply: bus
                    .publisher(&topics::vision_reply())
                    .context("opening the vision reply topic")?,
                state: bus
                    .publisher(&topics::vision_state())
                    .context("opening the vision state topic")?,
            },
        })
    }
}

impl Sinks {
    pub fn reply(&mut self, reply: VisionReply) -> Result<(), IpcError> {
        self.reply.publish(reply).map(|_| ())
    }

    /// Publishes the state, written in place (it is several KiB).
    pub fn state(&mut self, fill: impl FnOnce(&mut VisionState)) -> Result<(), IpcError> {
        self.state.publish_with(fill).map(|_| ())
    }
}
