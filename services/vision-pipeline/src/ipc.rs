//! Every bus call of the vision pipeline.
//!
//! | topic | direction | type |
//! |---|---|---|
//! | `skymesh/camera/{stream}/frames` | subscribe, only while the output is used | frames: `FrameHeader` + pixels, read in place |
//! | `skymesh/vision/demand` | subscribe | `VisionDemand` (consumers' word that they use the output) |
//! | `skymesh/vehicle/{id}/state` | subscribe | `VehicleState` (body attitude, height above home) |
//! | `skymesh/vision/control` | subscribe | `VisionControl` |
//! | `skymesh/vision/reply` | publish | `VisionReply` (one per control) |
//! | `skymesh/vision/view_control` | subscribe | `ViewControl` (settings of views, detector, tracker) |
//! | `skymesh/vision/view_reply` | publish | `ViewReply` (one per view control) |
//! | `skymesh/vision/state` | publish | `VisionState` (written in place) |
//! | `skymesh/vision/{stream}/output` | publish | output frames, rendered in place |

use anyhow::Context as _;
use skymesh_ipc_types::{
    topics, view, VehicleState, ViewControl, ViewReply, VisionControl, VisionDemand, VisionReply,
    VisionState, MAX_FRAME_LEN,
};
use skymesh_runtime::{Bus, FramePublisher, FrameSubscriber, IpcError, Publisher, Subscriber};

use crate::config::Settings;

/// One stream's frame ports.
#[derive(Debug)]
pub struct StreamPorts {
    name: String,
    /// Open only while the pipeline's output is used: the camera renders only while
    /// its frame topic has a subscriber.
    pub frames: Option<FrameSubscriber>,
    pub output: FramePublisher,
}

#[derive(Debug)]
pub struct Ports {
    bus: Bus,
    pub streams: Vec<StreamPorts>,
    pub vehicle: Subscriber<VehicleState>,
    pub control: Subscriber<VisionControl>,
    pub view: Subscriber<ViewControl>,
    pub demand: Subscriber<VisionDemand>,
    pub sinks: Sinks,
}

/// The pipeline's non-frame outputs (apart from the frame ports, so a frame can be
/// read in place while they are written).
#[derive(Debug)]
pub struct Sinks {
    reply: Publisher<VisionReply>,
    view_reply: Publisher<ViewReply>,
    state: Publisher<VisionState>,
}

impl Ports {
    pub fn open(bus: &Bus, s: &Settings) -> anyhow::Result<Ports> {
        let mut streams = Vec::with_capacity(s.streams.len());
        for st in &s.streams {
            streams.push(StreamPorts {
                name: st.name.clone(),
                frames: None,
                // Sized for the largest output VIDEO_OUTPUT may ask for, so a SET
                // never needs a new publisher.
                output: bus
                    .frame_publisher(&topics::vision_output(&st.name), MAX_FRAME_LEN)
                    .with_context(|| format!("opening the vision output of `{}`", st.name))?,
            });
        }
        Ok(Ports {
            bus: bus.clone(),
            streams,
            vehicle: bus
                .subscriber(&topics::vehicle_state(s.vehicle_id))
                .context("opening the vehicle state topic")?,
            control: bus
                .subscriber(&topics::vision_control())
                .context("opening the vision control topic")?,
            view: bus
                .subscriber(&view::view_control())
                .context("opening the view control topic")?,
            demand: bus
                .subscriber(&topics::vision_demand())
                .context("opening the vision demand topic")?,
            sinks: Sinks {
                reply: bus
                    .publisher(&topics::vision_reply())
                    .context("opening the vision reply topic")?,
                view_reply: bus
                    .publisher(&view::view_reply())
                    .context("opening the view reply topic")?,
                state: bus
                    .publisher(&topics::vision_state())
                    .context("opening the vision state topic")?,
            },
        })
    }
}

impl Ports {
    /// Opens (`on`) or closes every stream's frame subscriber; true if any changed.
    pub fn set_reading(&mut self, on: bool) -> anyhow::Result<bool> {
        let mut changed = false;
        for st in &mut self.streams {
            match (on, st.frames.is_some()) {
                (true, false) => {
                    st.frames = Some(
                        self.bus
                            .frame_subscriber(&topics::camera_frames(&st.name))
                            .with_context(|| {
                                format!("opening the camera frames of `{}`", st.name)
                            })?,
                    );
                    changed = true;
                }
                (false, true) => {
                    st.frames = None;
                    changed = true;
                }
                _ => {}
            }
        }
        Ok(changed)
    }

    /// Subscribers of any stream's output frames (a video consumer).
    pub fn output_readers(&self) -> usize {
        self.streams.iter().map(|s| s.output.subscribers()).sum()
    }
}

impl Sinks {
    pub fn reply(&mut self, reply: VisionReply) -> Result<(), IpcError> {
        self.reply.publish(reply).map(|_| ())
    }

    pub fn view_reply(&mut self, reply: ViewReply) -> Result<(), IpcError> {
        self.view_reply.publish(reply).map(|_| ())
    }

    /// Publishes the state, written in place (it is several KiB).
    pub fn state(&mut self, fill: impl FnOnce(&mut VisionState)) -> Result<(), IpcError> {
        self.state.publish_with(fill).map(|_| ())
    }
}
