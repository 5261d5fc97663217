//! The swarm queue's bus ports. All iceoryx2 calls stay in the runtime.
//!
//! Per drone: `skymesh/vehicle/{id}/{state,status,command_ack,arbiter_events}`
//! subscribed (the events answer the geofences the queue sends and say when its
//! emergency stop ended) and
//! `skymesh/vehicle/{id}/command` published, opened at start; the geofence
//! publisher of a vehicle only when the queue first sets its geofence (a
//! `GeofenceSet` is 4 KiB and every publisher reserves shared memory for its
//! subscribers' buffers). The hardware request publisher only exists when a
//! `hardware_drone` is configured.

use anyhow::Context as _;
use skymesh_ipc_types::{
    topics, ArbiterEvent, CommandAck, GeofenceSet, HardwareRequest, SwarmCommand, SwarmReply,
    SwarmState, SwarmWatch, VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::{Bus, IpcError, Publisher, Subscriber};

use crate::config::Settings;

/// One drone's vehicle topics.
#[derive(Debug)]
pub struct DronePorts {
    pub vehicle_id: u8,
    pub state: Subscriber<VehicleState>,
    pub status: Subscriber<VehicleStatus>,
    pub acks: Subscriber<CommandAck>,
    pub events: Subscriber<ArbiterEvent>,
    pub commands: Publisher<VehicleCommand>,
    /// Opened on first use.
    pub geofence: Option<Publisher<GeofenceSet>>,
}

/// Every topic the queue reads or writes.
pub struct Ports {
    /// From groundcontrol-gateway.
    pub swarm_commands: Subscriber<SwarmCommand>,
    pub replies: Publisher<SwarmReply>,
    pub state: Publisher<SwarmState>,
    /// The readers' words that they read the state at the tick rate.
    pub watch: Subscriber<SwarmWatch>,
    pub hardware: Option<Publisher<HardwareRequest>>,
    /// In the order of `Settings::drones`.
    pub drones: Vec<DronePorts>,
    bus: Bus,
}

impl core::fmt::Debug for Ports {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Ports")
            .field("drones", &self.drones.len())
            .finish_non_exhaustive()
    }
}

impl Ports {
    /// Opens (or creates) every topic of the queue and of its drones' vehicles. The
    /// per-vehicle ports are counted as one topic family each
    /// (`skymesh/vehicle/*/state`, …) so 250 drones keep the stats sample small
    /// enough for every swarm series.
    pub fn open(bus: &Bus, settings: &Settings) -> anyhow::Result<Ports> {
        let mut drones = Vec::with_capacity(settings.drones.len());
        for d in &settings.drones {
            let id = d.vehicle_id;
            drones.push(DronePorts {
                vehicle_id: id,
                state: bus
                    .subscriber_counted_as(&topics::vehicle_state(id), "skymesh/vehicle/*/state")
                    .with_context(|| format!("opening the state topic of vehicle {id}"))?,
                status: bus
                    .subscriber_counted_as(&topics::vehicle_status(id), "skymesh/vehicle/*/status")
                    .with_context(|| format!("opening the status topic of vehicle {id}"))?,
                acks: bus
                    .subscriber_counted_as(
                        &topics::vehicle_command_ack(id),
                        "skymesh/vehicle/*/command_ack",
                    )
                    .with_context(|| format!("opening the command ack topic of vehicle {id}"))?,
                events: bus
                    .subscriber_counted_as(
                        &topics::vehicle_arbiter_events(id),
                        "skymesh/vehicle/*/arbiter_events",
                    )
                    .with_context(|| format!("opening the arbiter events topic of vehicle {id}"))?,
                commands: bus
                    .publisher_counted_as(&topics::vehicle_command(id), "skymesh/vehicle/*/command")
                    .with_context(|| format!("opening the command topic of vehicle {id}"))?,
                geofence: None,
            });
        }
        Ok(Ports {
            swarm_commands: bus
                .subscriber(&topics::swarm_command())
                .context("opening the swarm command topic")?,
            replies: bus
                .publisher(&topics::swarm_reply())
                .context("opening the swarm reply topic")?,
            state: bus
                .publisher(&topics::swarm_state())
                .context("opening the swarm state topic")?,
            watch: bus
                .subscriber(&topics::swarm_watch())
                .context("opening the swarm watch topic")?,
            hardware: match settings.hardware_drone {
                Some(_) => Some(
                    bus.publisher(&topics::hardware_request())
                        .context("opening the hardware request topic")?,
                ),
                None => None,
            },
            drones,
            bus: bus.clone(),
        })
    }

    /// Publishes `g` on its vehicle's geofence topic (opened on first use).
    pub fn publish_geofence(&mut self, idx: usize, g: GeofenceSet) -> Result<(), IpcError> {
        let d = &mut self.drones[idx];
        let publisher = match &mut d.geofence {
            Some(p) => p,
            None => d.geofence.insert(self.bus.publisher_counted_as(
                &topics::vehicle_geofence(d.vehicle_id),
                "skymesh/vehicle/*/geofence",
            )?),
        };
        publisher.publish(g)?;
        Ok(())
    }
}
