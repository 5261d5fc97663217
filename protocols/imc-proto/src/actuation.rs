//! Actuation family: CameraZoom (300), SetThrusterActuation (301), SetServoPosition
//! (302), SetControlSurfaceDeflection (303), SetPWM (315), PWM (316).

use std::f32::consts::FRAC_PI_2;

use crate::catalog::check;
use crate::message::ids;
use crate::wire::{Reader, Writer};
use crate::{DecodeError, EncodeError, Message};

pub(crate) fn read(id: u16, r: &mut Reader<'_>) -> Result<Message, DecodeError> {
    Ok(match id {
        ids::CAMERA_ZOOM => Message::CameraZoom {
            id: r.u8("id")?,
            zoom: r.u8("zoom")?,
            action: r.enumeration("action")?,
        },
        ids::SET_THRUSTER_ACTUATION => Message::SetThrusterActuation {
            id: r.u8("id")?,
            value: r.f32("value")?,
        },
        ids::SET_SERVO_POSITION => Message::SetServoPosition {
            id: r.u8("id")?,
            value: r.f32("value")?,
        },
        ids::SET_CONTROL_SURFACE_DEFLECTION => Message::SetControlSurfaceDeflection {
            id: r.u8("id")?,
            angle: r.f32("angle")?,
        },
        ids::SET_PWM => Message::SetPwm {
            id: r.u8("id")?,
            period: r.u32("period")?,
            duty_cycle: r.u32("duty_cycle")?,
        },
        ids::PWM => Message::Pwm {
            id: r.u8("id")?,
            period: r.u32("period")?,
            duty_cycle: r.u32("duty_cycle")?,
        },
        other => return Err(DecodeError::UnknownId(other)),
    })
}

pub(crate) fn write(m: &Message, w: &mut Writer) -> Result<(), EncodeError> {
    match *m {
        Message::CameraZoom { id, zoom, action } => {
            w.u8(id);
            w.u8(zoom);
            w.u8(action.to_u8());
        }
        Message::SetThrusterActuation { id, value } | Message::SetServoPosition { id, value } => {
            w.u8(id);
            w.f32(value);
        }
        Message::SetControlSurfaceDeflection { id, angle } => {
            w.u8(id);
            w.f32(angle);
        }
        Message::SetPwm {
            id,
            period,
            duty_cycle,
        }
        | Message::Pwm {
            id,
            period,
            duty_cycle,
        } => {
            w.u8(id);
            w.u32(period);
            w.u32(duty_cycle);
        }
        _ => {}
    }
    Ok(())
}

/// Ranges from the document: thruster actuation −1..1, servo position −π/2..π/2 (as
/// `f32`, so a sender's `(float)M_PI_2` passes), control surface angle finite, PWM
/// duty cycle at most the period.
pub(crate) fn validate(m: &Message) -> Result<(), DecodeError> {
    let name = m.name();
    match *m {
        Message::SetThrusterActuation { value, .. } => {
            check((-1.0..=1.0).contains(&value), name, "value", value.into())
        }
        Message::SetServoPosition { value, .. } => check(
            (-FRAC_PI_2..=FRAC_PI_2).contains(&value),
            name,
            "value",
            value.into(),
        ),
        Message::SetControlSurfaceDeflection { angle, .. } => {
            check(angle.is_finite(), name, "angle", angle.into())
        }
        Message::SetPwm {
            period, duty_cycle, ..
        }
        | Message::Pwm {
            period, duty_cycle, ..
        } => check(duty_cycle <= period, name, "duty_cycle", duty_cycle.into()),
        _ => Ok(()),
    }
}
