//! Every bus call of the vision pipeline.
//!
//! | topic | direction | type |
//! |---|---|---|
//! | `skymesh/camera/{stream}/frames` | subscribe, only while the output is used | frames: `FrameHeader` + pixels, read in place |
//! | `skymesh/camera/{stream}/demand` | publish | `CameraDemand`: `wanted` when the frames are opened (renewed every second while read), not when closed |
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
    topics, view, CameraDemand, VehicleState, ViewControl, ViewReply, VisionControl, VisionDemand,
    VisionReply, VisionState, MAX_FRAME_LEN,
};
use skymesh_runtime::{Bus, FramePublisher, FrameSubscriber, IpcError, Publisher, Subscriber};

use crate::config::Settings;

/// One stream's frame ports.
#[derive(Debug)]
pub struct StreamPorts {
    name: String,
    /// Open only while the pipeline's output is used: the camera renders only while
    /// a reader wants its frames.
    pub frames: Option<FrameSubscriber>,
    /// The word to the camera that the frames are read (it sleeps without one).
    camera_demand: Publisher<CameraDemand>,
    pub output: FramePublisher,
}

impl StreamPorts {
    /// Tells the camera whether its frames are read now.
    fn camera_word(&mut self, wanted: bool) -> anyhow::Result<()> {
        self.camera_demand
            .publish(CameraDemand {
                wanted: u8::from(wanted),
                ..CameraDemand::default()
            })
            .with_context(|| format!("telling the camera of `{}` its demand", self.name))?;
        Ok(())
    }
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
                camera_demand: bus
                    .publisher(&topics::camera_demand(&st.name))
                    .with_context(|| format!("opening the camera demand of `{}`", st.name))?,
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
    /// Opens (`on`) or closes every stream's frame subscriber and tells the camera
    /// (after opening, so its first frame finds the subscriber; after closing, so it
    /// finds none left); true if any changed.
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
                    st.camera_word(true)?;
                    changed = true;
                }
                (false, true) => {
                    st.frames = None;
                    st.camera_word(false)?;
                    changed = true;
                }
                _ => {}
            }
        }
        Ok(changed)
    }

    /// Renews the camera's word of every stream that is read (its lease is a few
    /// seconds: a pipeline that died stops counting).
    pub fn renew_camera_demand(&mut self) -> anyhow::Result<()> {
        for st in self.streams.iter_mut().filter(|s| s.frames.is_some()) {
            st.camera_word(true)?;
        }
        Ok(())
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
