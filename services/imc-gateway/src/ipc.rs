//! Every bus call of imc-gateway, typed.
//!
//! | topic | direction | type |
//! |---|---|---|
//! | `skymesh/vehicle/{id}/command` | publish | `VehicleCommand` (source `imc`) |
//! | `skymesh/vehicle/{id}/command_ack` | subscribe | `CommandAck` |
//! | `skymesh/vehicle/{id}/state` | subscribe | `VehicleState` (yaw for teleoperation, Announce position) |
//! | `skymesh/vehicle/{id}/status` | subscribe | `VehicleStatus` (armed, mode) |
//! | `skymesh/input/buttons` | publish | `ButtonEvent` |
//! | `skymesh/hardware/request` | publish | `HardwareRequest` |
//! | `skymesh/hardware/reply` | subscribe | `HardwareReply` |
//! | `skymesh/hardware/state` | subscribe | `HardwareState` |

use anyhow::Context as _;
use skymesh_ipc_types::{
    topics, ButtonEvent, CommandAck, HardwareReply, HardwareRequest, HardwareState, SampleHeader,
    VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::{Bus, Publisher, Subscriber};

/// The gateway's ports; owned by its one loop.
#[derive(Debug)]
pub struct Ports {
    pub commands: Publisher<VehicleCommand>,
    pub buttons: Publisher<ButtonEvent>,
    pub hardware_requests: Publisher<HardwareRequest>,
    pub acks: Subscriber<CommandAck>,
    pub vehicle_state: Subscriber<VehicleState>,
    pub vehicle_status: Subscriber<VehicleStatus>,
    pub hardware_replies: Subscriber<HardwareReply>,
    pub hardware_state: Subscriber<HardwareState>,
    /// Our publishers' header fields (hardware replies for us carry them).
    pub origin: SampleHeader,
}

impl Ports {
    pub fn open(bus: &Bus, vehicle_id: u8) -> anyhow::Result<Ports> {
        let mut ports = Ports {
            commands: bus
                .publisher(&topics::vehicle_command(vehicle_id))
                .context("opening the vehicle command topic")?,
            buttons: bus
                .publisher(&topics::input_buttons())
                .context("opening the buttons topic")?,
            hardware_requests: bus
                .publisher(&topics::hardware_request())
                .context("opening the hardware request topic")?,
            acks: bus
                .subscriber(&topics::vehicle_command_ack(vehicle_id))
                .context("opening the command ack topic")?,
            vehicle_state: bus
                .subscriber(&topics::vehicle_state(vehicle_id))
                .context("opening the vehicle state topic")?,
            vehicle_status: bus
                .subscriber(&topics::vehicle_status(vehicle_id))
                .context("opening the vehicle status topic")?,
            hardware_replies: bus
                .subscriber(&topics::hardware_reply())
                .context("opening the hardware reply topic")?,
            hardware_state: bus
                .subscriber(&topics::hardware_state())
                .context("opening the hardware state topic")?,
            origin: bus.origin(),
        };
        // Read with `latest()` just before they are used: overwritten samples are by
        // design, not lost.
        ports.vehicle_state.set_newest_only();
        ports.vehicle_status.set_newest_only();
        Ok(ports)
    }
}
