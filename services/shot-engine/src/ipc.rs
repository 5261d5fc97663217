//! The shot engine's bus ports. All iceoryx2 calls stay in the runtime.

use anyhow::Context as _;
use skymesh_ipc_types::{
    topics, AppGeofence, AppSession, ArbiterEvent, AuthorityState, ButtonEvent, CommandAck,
    GeofenceSet, PayloadState, ShotEventSample, ShotRequestSample, ShotStatus, VehicleCommand,
    VehicleState, VehicleStatus,
};
use skymesh_runtime::{Bus, Publisher, Subscriber};

/// Every topic the engine reads or writes.
pub struct Ports {
    /// Protocol-neutral requests from the app gateways (solo-gateway: its TCP
    /// connection and follow stream).
    pub from_app: Subscriber<ShotRequestSample>,
    /// The app's geofence (GEOFENCE_SET_DATA), translated by solo-gateway.
    pub app_geofence: Subscriber<AppGeofence>,
    /// Whether an app is connected (solo-gateway, on change and every second).
    pub app_session: Subscriber<AppSession>,
    /// Controller buttons (IMC gateway, tools).
    pub buttons: Subscriber<ButtonEvent>,
    /// From autopilot-link: the vehicle.
    pub state: Subscriber<VehicleState>,
    pub status: Subscriber<VehicleStatus>,
    pub payload: Subscriber<PayloadState>,
    /// From autopilot-link's arbiter: who holds authority, what it did, our answers.
    pub authority: Subscriber<AuthorityState>,
    pub events: Subscriber<ArbiterEvent>,
    pub acks: Subscriber<CommandAck>,
    /// To autopilot-link's arbiter (source `ShotEngine`).
    pub commands: Publisher<VehicleCommand>,
    /// The app's geofence for autopilot-link's arbiter (source `ShotEngine`).
    pub geofence: Publisher<GeofenceSet>,
    /// Events for the app gateways, which translate them for their apps.
    pub to_app: Publisher<ShotEventSample>,
    /// What the engine is doing (latest value).
    pub shot_status: Publisher<ShotStatus>,
}

impl core::fmt::Debug for Ports {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Ports").finish_non_exhaustive()
    }
}

impl Ports {
    /// Opens (or creates) every topic of vehicle `id`.
    pub fn open(bus: &Bus, id: u8) -> anyhow::Result<Ports> {
        let mut ports = Ports {
            from_app: bus
                .subscriber(&topics::shot_requests())
                .context("opening the shot requests topic")?,
            app_geofence: bus
                .subscriber(&topics::shot_app_geofence())
                .context("opening the app geofence topic")?,
            app_session: bus
                .subscriber(&topics::shot_app_session())
                .context("opening the app session topic")?,
            buttons: bus
                .subscriber(&topics::input_buttons())
                .context("opening the buttons topic")?,
            state: bus
                .subscriber(&topics::vehicle_state(id))
                .context("opening the vehicle state topic")?,
            status: bus
                .subscriber(&topics::vehicle_status(id))
                .context("opening the vehicle status topic")?,
            payload: bus
                .subscriber(&topics::vehicle_payload(id))
                .context("opening the payload topic")?,
            authority: bus
                .subscriber(&topics::vehicle_authority(id))
                .context("opening the authority topic")?,
            events: bus
                .subscriber(&topics::vehicle_arbiter_events(id))
                .context("opening the arbiter events topic")?,
            acks: bus
                .subscriber(&topics::vehicle_command_ack(id))
                .context("opening the command ack topic")?,
            commands: bus
                .publisher(&topics::vehicle_command(id))
                .context("opening the vehicle command topic")?,
            geofence: bus
                .publisher(&topics::vehicle_geofence(id))
                .context("opening the vehicle geofence topic")?,
            to_app: bus
                .publisher(&topics::shot_events())
                .context("opening the shot events topic")?,
            shot_status: bus
                .publisher(&topics::shot_status())
                .context("opening the shot status topic")?,
        };
        // Read with `latest()` at the engine's tick (or slower while idle): older
        // samples overwritten in between are by design, not lost.
        ports.state.set_newest_only();
        ports.payload.set_newest_only();
        Ok(ports)
    }
}

#[cfg(test)]
mod tests {
    use skymesh_ipc_types::ShotEvent;

    use super::*;

    #[test]
    fn the_longest_error_text_fits_the_bus() {
        let text = "x".repeat(crate::engine::MAX_ERROR_TEXT);
        let s = ShotEventSample::new(0, &ShotEvent::Error(text.clone()));
        assert_eq!(s.event(), Ok(ShotEvent::Error(text)));
    }
}
