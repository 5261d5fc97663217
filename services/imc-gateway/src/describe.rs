//! Names and one-line descriptions of IMC messages: metric labels and what the
//! `skymesh-imc` client prints.

use imc_proto::Message;

/// The IMC abbreviation of a message (the `message` label of
/// `skymesh_imc_messages_total`).
pub fn message_name(m: &Message) -> &'static str {
    match m {
        Message::Heartbeat => "Heartbeat",
        Message::Announce(_) => "Announce",
        Message::CameraZoom { .. } => "CameraZoom",
        Message::SetThrusterActuation { .. } => "SetThrusterActuation",
        Message::SetServoPosition { .. } => "SetServoPosition",
        Message::SetControlSurfaceDeflection { .. } => "SetControlSurfaceDeflection",
        Message::RemoteActionsRequest { .. } => "RemoteActionsRequest",
        Message::RemoteActions { .. } => "RemoteActions",
        Message::ButtonEvent { .. } => "ButtonEvent",
        Message::LcdControl { .. } => "LcdControl",
        Message::PowerOperation { .. } => "PowerOperation",
        Message::PowerChannelControl { .. } => "PowerChannelControl",
        Message::QueryPowerChannelState => "QueryPowerChannelState",
        Message::PowerChannelState { .. } => "PowerChannelState",
        Message::LedBrightness { .. } => "LedBrightness",
        Message::QueryLedBrightness { .. } => "QueryLedBrightness",
        Message::SetLedBrightness { .. } => "SetLedBrightness",
        Message::SetPwm { .. } => "SetPWM",
        Message::Pwm { .. } => "PWM",
        Message::GpioState { .. } => "GpioState",
        Message::GpioStateGet { .. } => "GpioStateGet",
        Message::GpioStateSet { .. } => "GpioStateSet",
    }
}

/// One line: the name and the fields, e.g. `LedBrightness name=status value=200`.
pub fn describe(m: &Message) -> String {
    let n = message_name(m);
    match m {
        Message::Heartbeat | Message::QueryPowerChannelState => n.to_string(),
        Message::Announce(a) => format!(
            "{n} sys_name={:?} sys_type={:?} owner={:#06x} lat={:.7}° lon={:.7}° height={}m services={:?}",
            a.sys_name,
            a.sys_type,
            a.owner,
            a.lat.to_degrees(),
            a.lon.to_degrees(),
            a.height,
            a.services
        ),
        Message::CameraZoom { id, zoom, action } => {
            format!("{n} id={id} zoom={zoom} action={action:?}")
        }
        Message::SetThrusterActuation { id, value } | Message::SetServoPosition { id, value } => {
            format!("{n} id={id} value={value}")
        }
        Message::SetControlSurfaceDeflection { id, angle } => format!("{n} id={id} angle={angle}"),
        Message::RemoteActionsRequest { op, actions } => {
            format!("{n} op={op:?} actions={actions:?}")
        }
        Message::RemoteActions { actions } => format!("{n} actions={actions:?}"),
        Message::ButtonEvent { button, value } => format!("{n} button={button} value={value}"),
        Message::LcdControl { op, text } => format!("{n} op={op:?} text={text:?}"),
        Message::PowerOperation {
            op,
            time_remain,
            sched_time,
        } => format!("{n} op={op:?} time_remain={time_remain}s sched_time={sched_time}"),
        Message::PowerChannelControl {
            name,
            op,
            sched_time,
        } => format!("{n} name={name} op={op:?} sched_time={sched_time}"),
        Message::PowerChannelState { name, state } => format!("{n} name={name} state={state:?}"),
        Message::LedBrightness { name, value }
        | Message::SetLedBrightness { name, value }
        | Message::GpioState { name, value }
        | Message::GpioStateSet { name, value } => format!("{n} name={name} value={value}"),
        Message::QueryLedBrightness { name } | Message::GpioStateGet { name } => {
            format!("{n} name={name}")
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
        } => format!("{n} id={id} period={period}us duty_cycle={duty_cycle}us"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_name_the_message_and_its_fields() {
        assert_eq!(
            describe(&Message::LedBrightness {
                name: "status".into(),
                value: 200
            }),
            "LedBrightness name=status value=200"
        );
        assert_eq!(
            describe(&Message::Pwm {
                id: 0,
                period: 20000,
                duty_cycle: 1500
            }),
            "PWM id=0 period=20000us duty_cycle=1500us"
        );
        assert_eq!(describe(&Message::Heartbeat), "Heartbeat");
    }
}
