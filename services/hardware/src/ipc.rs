//! Every bus call of the hardware service.
//!
//! | topic | direction | type |
//! |---|---|---|
//! | `skymesh/hardware/request` | subscribe | `HardwareRequest` (any gateway) |
//! | `skymesh/hardware/reply` | publish | `HardwareReply` (one per request) |
//! | `skymesh/hardware/state` | publish | `HardwareState` (on change and at 1 Hz) |

use anyhow::Context as _;
use skymesh_ipc_types::{topics, HardwareReply, HardwareRequest, HardwareState};
use skymesh_runtime::{Bus, IpcError, Publisher, Subscriber};

#[derive(Debug)]
pub(crate) struct Ports {
    pub requests: Subscriber<HardwareRequest>,
    replies: Publisher<HardwareReply>,
    state: Publisher<HardwareState>,
}

impl Ports {
    pub fn open(bus: &Bus) -> anyhow::Result<Ports> {
        Ok(Ports {
            requests: bus
                .subscriber::<HardwareRequest>(&topics::hardware_request())
                .context("opening the hardware request topic")?,
            replies: bus
                .publisher::<HardwareReply>(&topics::hardware_reply())
                .context("opening the hardware reply topic")?,
            state: bus
                .publisher::<HardwareState>(&topics::hardware_state())
                .context("opening the hardware state topic")?,
        })
    }

    pub fn reply(&mut self, reply: HardwareReply) -> Result<(), IpcError> {
        self.replies.publish(reply).map(|_| ())
    }

    pub fn state(&mut self, state: HardwareState) -> Result<(), IpcError> {
        self.state.publish(state).map(|_| ())
    }
}
