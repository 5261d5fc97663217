//! Power family: PowerOperation (308), PowerChannelControl (309),
//! QueryPowerChannelState (310), PowerChannelState (311).

use crate::catalog::check;
use crate::message::ids;
use crate::wire::{Reader, Writer};
use crate::{DecodeError, EncodeError, Message};

pub(crate) fn read(id: u16, r: &mut Reader<'_>) -> Result<Message, DecodeError> {
    Ok(match id {
        ids::POWER_OPERATION => Message::PowerOperation {
            op: r.enumeration("op")?,
            time_remain: r.f32("time_remain")?,
            sched_time: r.f64("sched_time")?,
        },
        ids::POWER_CHANNEL_CONTROL => Message::PowerChannelControl {
            name: r.plaintext("name")?,
            op: r.enumeration("op")?,
            sched_time: r.f64("sched_time")?,
        },
        ids::QUERY_POWER_CHANNEL_STATE => Message::QueryPowerChannelState,
        ids::POWER_CHANNEL_STATE => Message::PowerChannelState {
            name: r.plaintext("name")?,
            state: r.enumeration("state")?,
        },
        other => return Err(DecodeError::UnknownId(other)),
    })
}

pub(crate) fn write(m: &Message, w: &mut Writer) -> Result<(), EncodeError> {
    match m {
        Message::PowerOperation {
            op,
            time_remain,
            sched_time,
        } => {
            w.u8(op.to_u8());
            w.f32(*time_remain);
            w.f64(*sched_time);
        }
        Message::PowerChannelControl {
            name,
            op,
            sched_time,
        } => {
            w.plaintext("name", name)?;
            w.u8(op.to_u8());
            w.f64(*sched_time);
        }
        Message::PowerChannelState { name, state } => {
            w.plaintext("name", name)?;
            w.u8(state.to_u8());
        }
        _ => {}
    }
    Ok(())
}

/// Times must be finite; a channel's schedule is "in `sched_time` seconds", so it
/// cannot be negative. `PowerChannelControl.op` accepts RESTART (7) although the
/// document's range column says max=6: its own enumeration lists 7.
pub(crate) fn validate(m: &Message) -> Result<(), DecodeError> {
    let name = m.name();
    match *m {
        Message::PowerOperation {
            time_remain,
            sched_time,
            ..
        } => {
            check(
                time_remain.is_finite(),
                name,
                "time_remain",
                time_remain.into(),
            )?;
            check(sched_time.is_finite(), name, "sched_time", sched_time)
        }
        Message::PowerChannelControl { sched_time, .. } => check(
            sched_time.is_finite() && sched_time >= 0.0,
            name,
            "sched_time",
            sched_time,
        ),
        _ => Ok(()),
    }
}
