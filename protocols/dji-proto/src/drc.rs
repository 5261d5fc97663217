//! `parse_drc` (`drc/down`) and `parse_event_reply` (`events_reply`).

use std::ops::RangeInclusive;

use crate::check::{int_value, no_data, reject, unknown_method, Obj};
use crate::codes::MISSING_FIELD;
use crate::requests::{DrcDown, DroneControl, EventReply};
use crate::{Envelope, Reject};

/// Stick limits of `drone_control` (the document's; `h` is listed as min 5, max −4).
pub(crate) const STICK_XY_MAX: f64 = 17.0;
pub(crate) const STICK_H_MIN: f64 = -4.0;
pub(crate) const STICK_H_MAX: f64 = 5.0;
pub(crate) const STICK_W_MAX: f64 = 90.0;

pub(crate) fn parse(env: &Envelope) -> Result<DrcDown, Reject> {
    match env.method.as_str() {
        "drone_control" => {
            let o = Obj::data(&env.data)?;
            Ok(DrcDown::DroneControl(DroneControl {
                seq: seq(&o, env, 0..=i64::MAX)?,
                x: o.num("x", -STICK_XY_MAX, STICK_XY_MAX)?,
                y: o.num("y", -STICK_XY_MAX, STICK_XY_MAX)?,
                h: o.num("h", STICK_H_MIN, STICK_H_MAX)?,
                w: o.num("w", -STICK_W_MAX, STICK_W_MAX)?,
            }))
        }
        "drone_emergency_stop" => no_data(&env.data).map(|()| DrcDown::DroneEmergencyStop),
        "heart_beat" => {
            let o = Obj::data(&env.data)?;
            Ok(DrcDown::HeartBeat {
                seq: seq(&o, env, i64::MIN..=i64::MAX)?,
                timestamp: o.int("timestamp", i64::MIN..=i64::MAX)?,
            })
        }
        other => Err(unknown_method(other)),
    }
}

/// `data.seq`, else the envelope's top-level `seq`; required.
fn seq(o: &Obj<'_>, env: &Envelope, range: RangeInclusive<i64>) -> Result<i64, Reject> {
    if o.opt("seq").is_some() {
        return o.int("seq", range);
    }
    match env.seq {
        Some(top) => int_value(&top.into(), "seq", range),
        None => Err(reject(MISSING_FIELD, o.path_of("seq"), "required")),
    }
}

pub(crate) fn parse_event_reply(env: &Envelope) -> Result<EventReply, Reject> {
    let o = Obj::data(&env.data)?;
    Ok(EventReply {
        tid: env.tid.clone(),
        bid: env.bid.clone(),
        method: env.method.clone(),
        result: o.int("result", i64::MIN..=i64::MAX)?,
    })
}
