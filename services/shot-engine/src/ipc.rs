//! The shot engine's bus ports, and the one conversion the engine's outputs need
//! (a `SoloMessage` into an `AppMessage`). All iceoryx2 calls stay in the runtime.

use anyhow::Context as _;
use bytes::BytesMut;
use skymesh_ipc_types::shot::ValueTooLong;
use skymesh_ipc_types::{
    topics, AppGeofence, AppMessage, AppSession, ArbiterEvent, AuthorityState, ButtonEvent,
    CommandAck, GeofenceSet, PayloadState, ShotStatus, VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::{Bus, Publisher, Subscriber};
use solo_proto::SoloMessage;

/// Every topic the engine reads or writes.
pub struct Ports {
    /// Decoded, validated app messages from solo-gateway (TCP and follow stream).
    pub from_app: Subscriber<AppMessage>,
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
    /// To solo-gateway, which writes them to the app.
    pub to_app: Publisher<AppMessage>,
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
                .subscriber(&topics::shot_from_app())
                .context("opening the from-app topic")?,
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
                .publisher(&topics::shot_to_app())
                .context("opening the to-app topic")?,
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

/// `msg` as a bus sample for whichever app is connected (session 0).
pub fn app_message(msg: &SoloMessage) -> Result<AppMessage, ValueTooLong> {
    let mut value = BytesMut::new();
    msg.encode_value(&mut value);
    AppMessage::new(0, msg.msg_type(), &value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn app_messages_carry_the_type_and_value() {
        let m = app_message(&SoloMessage::GetCurrentShot(-1)).unwrap();
        assert_eq!(m.session, 0);
        assert_eq!(m.msg_type, solo_proto::ids::GET_CURRENT_SHOT);
        assert_eq!(m.value(), (-1i32).to_le_bytes());
        assert_eq!(
            SoloMessage::decode(m.msg_type, m.value()).unwrap(),
            SoloMessage::GetCurrentShot(-1)
        );
    }

    #[test]
    fn the_longest_error_text_fits_the_bus() {
        let text = "x".repeat(crate::engine::MAX_ERROR_TEXT);
        assert!(app_message(&SoloMessage::ShotManagerError(text)).is_ok());
    }
}
