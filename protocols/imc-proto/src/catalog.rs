//! Per message id: its name and the family file that reads, writes and checks it.

use crate::message::ids;
use crate::wire::{Reader, Writer};
use crate::{actuation, devices, power, system, teleop};
use crate::{DecodeError, EncodeError, Message};

/// Which file holds a message's fields.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Family {
    System,
    Actuation,
    Teleop,
    Power,
    Devices,
}

/// Every implemented message: id, IMC name, family. Ascending ids.
const CATALOG: &[(u16, &str, Family)] = &[
    (ids::HEARTBEAT, "Heartbeat", Family::System),
    (ids::ANNOUNCE, "Announce", Family::System),
    (ids::CAMERA_ZOOM, "CameraZoom", Family::Actuation),
    (
        ids::SET_THRUSTER_ACTUATION,
        "SetThrusterActuation",
        Family::Actuation,
    ),
    (
        ids::SET_SERVO_POSITION,
        "SetServoPosition",
        Family::Actuation,
    ),
    (
        ids::SET_CONTROL_SURFACE_DEFLECTION,
        "SetControlSurfaceDeflection",
        Family::Actuation,
    ),
    (
        ids::REMOTE_ACTIONS_REQUEST,
        "RemoteActionsRequest",
        Family::Teleop,
    ),
    (ids::REMOTE_ACTIONS, "RemoteActions", Family::Teleop),
    (ids::BUTTON_EVENT, "ButtonEvent", Family::Teleop),
    (ids::LCD_CONTROL, "LcdControl", Family::Devices),
    (ids::POWER_OPERATION, "PowerOperation", Family::Power),
    (
        ids::POWER_CHANNEL_CONTROL,
        "PowerChannelControl",
        Family::Power,
    ),
    (
        ids::QUERY_POWER_CHANNEL_STATE,
        "QueryPowerChannelState",
        Family::Power,
    ),
    (ids::POWER_CHANNEL_STATE, "PowerChannelState", Family::Power),
    (ids::LED_BRIGHTNESS, "LedBrightness", Family::Devices),
    (
        ids::QUERY_LED_BRIGHTNESS,
        "QueryLedBrightness",
        Family::Devices,
    ),
    (ids::SET_LED_BRIGHTNESS, "SetLedBrightness", Family::Devices),
    (ids::SET_PWM, "SetPWM", Family::Actuation),
    (ids::PWM, "PWM", Family::Actuation),
    (ids::GPIO_STATE, "GpioState", Family::Devices),
    (ids::GPIO_STATE_GET, "GpioStateGet", Family::Devices),
    (ids::GPIO_STATE_SET, "GpioStateSet", Family::Devices),
];

fn entry(id: u16) -> Option<&'static (u16, &'static str, Family)> {
    CATALOG.iter().find(|(i, _, _)| *i == id)
}

/// The IMC name of an implemented message id (`SetPWM` for 315), `None` otherwise.
pub fn message_name(id: u16) -> Option<&'static str> {
    entry(id).map(|(_, name, _)| *name)
}

/// Every implemented message id, ascending.
pub fn known_ids() -> impl Iterator<Item = u16> {
    CATALOG.iter().map(|(id, _, _)| *id)
}

/// Reads the fields of message `id` (the id itself already read). Range checks are
/// [`Message::validate`]'s; enumerations are checked here.
pub(crate) fn read_fields(id: u16, r: &mut Reader<'_>) -> Result<Message, DecodeError> {
    match entry(id).map(|(_, _, family)| *family) {
        Some(Family::System) => system::read(id, r),
        Some(Family::Actuation) => actuation::read(id, r),
        Some(Family::Teleop) => teleop::read(id, r),
        Some(Family::Power) => power::read(id, r),
        Some(Family::Devices) => devices::read(id, r),
        None => Err(DecodeError::UnknownId(id)),
    }
}

/// Writes the fields of `m` (not its id).
pub(crate) fn write_fields(m: &Message, w: &mut Writer) -> Result<(), EncodeError> {
    match family(m) {
        Family::System => system::write(m, w),
        Family::Actuation => actuation::write(m, w),
        Family::Teleop => teleop::write(m, w),
        Family::Power => power::write(m, w),
        Family::Devices => devices::write(m, w),
    }
}

fn family(m: &Message) -> Family {
    match m {
        Message::Heartbeat | Message::Announce(_) => Family::System,
        Message::CameraZoom { .. }
        | Message::SetThrusterActuation { .. }
        | Message::SetServoPosition { .. }
        | Message::SetControlSurfaceDeflection { .. }
        | Message::SetPwm { .. }
        | Message::Pwm { .. } => Family::Actuation,
        Message::RemoteActionsRequest { .. }
        | Message::RemoteActions { .. }
        | Message::ButtonEvent { .. } => Family::Teleop,
        Message::PowerOperation { .. }
        | Message::PowerChannelControl { .. }
        | Message::QueryPowerChannelState
        | Message::PowerChannelState { .. } => Family::Power,
        Message::LcdControl { .. }
        | Message::LedBrightness { .. }
        | Message::QueryLedBrightness { .. }
        | Message::SetLedBrightness { .. }
        | Message::GpioState { .. }
        | Message::GpioStateGet { .. }
        | Message::GpioStateSet { .. } => Family::Devices,
    }
}

impl Message {
    /// The IMC message id.
    pub fn id(&self) -> u16 {
        match self {
            Message::Heartbeat => ids::HEARTBEAT,
            Message::Announce(_) => ids::ANNOUNCE,
            Message::CameraZoom { .. } => ids::CAMERA_ZOOM,
            Message::SetThrusterActuation { .. } => ids::SET_THRUSTER_ACTUATION,
            Message::SetServoPosition { .. } => ids::SET_SERVO_POSITION,
            Message::SetControlSurfaceDeflection { .. } => ids::SET_CONTROL_SURFACE_DEFLECTION,
            Message::RemoteActionsRequest { .. } => ids::REMOTE_ACTIONS_REQUEST,
            Message::RemoteActions { .. } => ids::REMOTE_ACTIONS,
            Message::ButtonEvent { .. } => ids::BUTTON_EVENT,
            Message::LcdControl { .. } => ids::LCD_CONTROL,
            Message::PowerOperation { .. } => ids::POWER_OPERATION,
            Message::PowerChannelControl { .. } => ids::POWER_CHANNEL_CONTROL,
            Message::QueryPowerChannelState => ids::QUERY_POWER_CHANNEL_STATE,
            Message::PowerChannelState { .. } => ids::POWER_CHANNEL_STATE,
            Message::LedBrightness { .. } => ids::LED_BRIGHTNESS,
            Message::QueryLedBrightness { .. } => ids::QUERY_LED_BRIGHTNESS,
            Message::SetLedBrightness { .. } => ids::SET_LED_BRIGHTNESS,
            Message::SetPwm { .. } => ids::SET_PWM,
            Message::Pwm { .. } => ids::PWM,
            Message::GpioState { .. } => ids::GPIO_STATE,
            Message::GpioStateGet { .. } => ids::GPIO_STATE_GET,
            Message::GpioStateSet { .. } => ids::GPIO_STATE_SET,
        }
    }

    /// The IMC message name (`SetPWM`, `GpioStateSet`, …), for logs and metric labels.
    pub fn name(&self) -> &'static str {
        message_name(self.id()).unwrap_or("unknown")
    }

    /// The checks decoding applies beyond enumerations: every float finite and inside
    /// the document's range, PWM duty cycle within the period. [`crate::encode_datagram`]
    /// does not call it; call it before sending values that did not come from a
    /// decoded message.
    pub fn validate(&self) -> Result<(), DecodeError> {
        match family(self) {
            Family::System => system::validate(self),
            Family::Actuation => actuation::validate(self),
            Family::Teleop => Ok(()),
            Family::Power => power::validate(self),
            Family::Devices => Ok(()),
        }
    }
}

/// A [`DecodeError::InvalidValue`] unless `ok`.
pub(crate) fn check(
    ok: bool,
    message: &'static str,
    field: &'static str,
    value: f64,
) -> Result<(), DecodeError> {
    if ok {
        Ok(())
    } else {
        Err(DecodeError::InvalidValue {
            message,
            field,
            value,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catalog_ids_are_ascending_and_names_unique() {
        assert!(CATALOG.windows(2).all(|w| w[0].0 < w[1].0));
        let mut names: Vec<&str> = CATALOG.iter().map(|e| e.1).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), CATALOG.len());
        assert_eq!(message_name(ids::SET_PWM), Some("SetPWM"));
        assert_eq!(message_name(0), None);
    }
}
