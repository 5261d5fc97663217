//! What autopilot-link asks of the autopilot on its own: our HEARTBEAT, telemetry
//! rates and the home position. Pure message builders.
//!
//! ArduPilot (and SITL) streams little until asked. Rates are requested per message
//! with `MAV_CMD_SET_MESSAGE_INTERVAL` and, for firmware that predates it, per
//! stream group with `REQUEST_DATA_STREAM` (sent first, so the per-message
//! intervals win where both are understood).

use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavState, MavType, ATTITUDE_DATA,
    BATTERY_STATUS_DATA, COMMAND_LONG_DATA, EKF_STATUS_REPORT_DATA,
    GIMBAL_DEVICE_ATTITUDE_STATUS_DATA, GLOBAL_POSITION_INT_DATA, GPS_RAW_INT_DATA, HEARTBEAT_DATA,
    HOME_POSITION_DATA, LOCAL_POSITION_NED_DATA, SYS_STATUS_DATA,
};
use mavlink::MessageData;

use crate::commands::Target;
use crate::config::StreamRates;

/// MAVLink component id we send as (`MAV_COMP_ID_ONBOARD_COMPUTER`).
pub const OWN_COMPONENT: u8 = 191;

/// Our 1 Hz HEARTBEAT: an onboard controller, not an autopilot.
pub fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

fn command_long(t: Target, command: MavCmd, param1: f32, param2: f32) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1,
        param2,
        command,
        target_system: t.system,
        target_component: t.component,
        ..Default::default()
    })
}

/// `MAV_CMD_REQUEST_MESSAGE` for one HOME_POSITION.
pub fn request_home(t: Target) -> MavMessage {
    command_long(
        t,
        MavCmd::MAV_CMD_REQUEST_MESSAGE,
        HOME_POSITION_DATA::ID as f32,
        0.0,
    )
}

/// The messages that ask for every telemetry stream at `rates`. The gimbal attitude
/// (GIMBAL_DEVICE_ATTITUDE_STATUS, which ArduPilot sends for the mount it drives) and
/// the HEARTBEAT are asked for only with SET_MESSAGE_INTERVAL, and only when a rate is
/// configured. ArduPilot sends its HEARTBEAT once a second unless asked, and that
/// heartbeat is how the mesh learns the flight mode: a pilot's switch to LOITER or RTL
/// would stay unknown to the shot engine, the gateways and the swarm queue for up
/// to a second. The interval applies to the link it was asked on only.
///
/// ATTITUDE (and with it `VehicleState`) goes at the ground rate while the vehicle
/// is `armed == false`: a vehicle standing on the ground needs no 50 Hz attitude, and
/// every ATTITUDE wakes the autopilot-link (and a simulator) on an otherwise idle
/// companion computer. Arming asks for the flight rate again.
pub fn stream_requests(
    rates: &StreamRates,
    t: Target,
    legacy: bool,
    armed: bool,
) -> Vec<MavMessage> {
    let rates = &StreamRates {
        attitude_hz: if armed {
            rates.attitude_hz
        } else {
            rates.ground_attitude_hz.unwrap_or(rates.attitude_hz)
        },
        ..*rates
    };
    let mut out = Vec::with_capacity(13);
    if legacy {
        out.extend(legacy_stream_requests(rates, t));
    }
    let gimbal = rates
        .gimbal_attitude_hz
        .map(|hz| (GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID, hz));
    let heartbeat = rates.heartbeat_hz.map(|hz| (HEARTBEAT_DATA::ID, hz));
    for (id, hz) in [
        (ATTITUDE_DATA::ID, rates.attitude_hz),
        (GLOBAL_POSITION_INT_DATA::ID, rates.global_position_hz),
        (LOCAL_POSITION_NED_DATA::ID, rates.local_position_hz),
        (SYS_STATUS_DATA::ID, rates.sys_status_hz),
        (BATTERY_STATUS_DATA::ID, rates.battery_status_hz),
        (GPS_RAW_INT_DATA::ID, rates.gps_raw_hz),
        (EKF_STATUS_REPORT_DATA::ID, rates.ekf_status_hz),
    ]
    .into_iter()
    .chain(gimbal)
    .chain(heartbeat)
    {
        let interval_us = (1e6 / f64::from(hz)).round() as f32;
        out.push(command_long(
            t,
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            id as f32,
            interval_us,
        ));
    }
    out
}

/// REQUEST_DATA_STREAM per ArduPilot stream group (deprecated in MAVLink since 2015,
/// still honoured by ArduPilot).
#[allow(deprecated)]
fn legacy_stream_requests(rates: &StreamRates, t: Target) -> Vec<MavMessage> {
    use mavlink::dialects::ardupilotmega::{MavDataStream, REQUEST_DATA_STREAM_DATA};
    // Whole Hz only; never 0 (which would stop the stream).
    let hz = |r: f32| r.ceil().clamp(1.0, f32::from(u16::MAX)) as u16;
    [
        // ATTITUDE (+ AHRS2, SIMSTATE on ArduPilot).
        (MavDataStream::MAV_DATA_STREAM_EXTRA1, hz(rates.attitude_hz)),
        // GLOBAL_POSITION_INT, LOCAL_POSITION_NED.
        (
            MavDataStream::MAV_DATA_STREAM_POSITION,
            hz(rates.global_position_hz.max(rates.local_position_hz)),
        ),
        // SYS_STATUS, GPS_RAW_INT, ...
        (
            MavDataStream::MAV_DATA_STREAM_EXTENDED_STATUS,
            hz(rates.sys_status_hz.max(rates.gps_raw_hz)),
        ),
        // BATTERY_STATUS, EKF_STATUS_REPORT, ...
        (
            MavDataStream::MAV_DATA_STREAM_EXTRA3,
            hz(rates.battery_status_hz.max(rates.ekf_status_hz)),
        ),
    ]
    .into_iter()
    .map(|(stream, rate)| {
        MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
            req_message_rate: rate,
            target_system: t.system,
            target_component: t.component,
            req_stream_id: stream,
            start_stop: 1,
        })
    })
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::Message;

    const T: Target = Target {
        system: 3,
        component: 1,
    };

    fn rates() -> StreamRates {
        StreamRates {
            attitude_hz: 50.0,
            ground_attitude_hz: Some(10.0),
            global_position_hz: 10.0,
            local_position_hz: 5.0,
            sys_status_hz: 2.0,
            battery_status_hz: 0.5,
            gps_raw_hz: 2.0,
            ekf_status_hz: 2.5,
            gimbal_attitude_hz: Some(10.0),
            heartbeat_hz: Some(5.0),
        }
    }

    #[test]
    fn every_stream_gets_a_message_interval() {
        let msgs = stream_requests(&rates(), T, false, true);
        assert_eq!(msgs.len(), 9);
        let intervals: Vec<(f32, f32)> = msgs
            .iter()
            .map(|m| match m {
                MavMessage::COMMAND_LONG(c) => {
                    assert_eq!(c.command, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL);
                    assert_eq!((c.target_system, c.target_component), (3, 1));
                    (c.param1, c.param2)
                }
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(intervals[0], (30.0, 20_000.0), "ATTITUDE at 50 Hz");
        assert_eq!(
            intervals[1],
            (33.0, 100_000.0),
            "GLOBAL_POSITION_INT at 10 Hz"
        );
        assert_eq!(
            intervals[4],
            (147.0, 2_000_000.0),
            "BATTERY_STATUS at 0.5 Hz"
        );
        assert_eq!(
            intervals[6],
            (193.0, 400_000.0),
            "EKF_STATUS_REPORT at 2.5 Hz"
        );
        assert_eq!(
            intervals[7],
            (285.0, 100_000.0),
            "GIMBAL_DEVICE_ATTITUDE_STATUS at 10 Hz"
        );
        assert_eq!(intervals[8], (0.0, 200_000.0), "HEARTBEAT at 5 Hz");
        let none = StreamRates {
            gimbal_attitude_hz: None,
            heartbeat_hz: None,
            ..rates()
        };
        assert_eq!(
            stream_requests(&none, T, false, true).len(),
            7,
            "0 = not asked"
        );
    }

    fn attitude_interval_us(msgs: &[MavMessage]) -> f32 {
        msgs.iter()
            .find_map(|m| match m {
                MavMessage::COMMAND_LONG(c) if c.param1 == ATTITUDE_DATA::ID as f32 => {
                    Some(c.param2)
                }
                _ => None,
            })
            .expect("an ATTITUDE interval")
    }

    #[test]
    #[allow(deprecated)]
    fn attitude_goes_at_the_ground_rate_while_disarmed() {
        let ground = stream_requests(&rates(), T, true, false);
        assert_eq!(
            attitude_interval_us(&ground),
            100_000.0,
            "10 Hz on the ground"
        );
        let MavMessage::REQUEST_DATA_STREAM(extra1) = &ground[0] else {
            panic!("{:?}", ground[0])
        };
        assert_eq!(
            extra1.req_message_rate, 10,
            "legacy EXTRA1 at the ground rate"
        );
        let flying = stream_requests(&rates(), T, false, true);
        assert_eq!(attitude_interval_us(&flying), 20_000.0, "50 Hz armed");
        // Every other stream is the same on the ground and in flight.
        assert_eq!(ground[4..].len(), flying.len());
        for (g, f) in ground[4..].iter().zip(&flying).skip(1) {
            assert_eq!(g, f);
        }
        let no_ground_rate = StreamRates {
            ground_attitude_hz: None,
            ..rates()
        };
        assert_eq!(
            attitude_interval_us(&stream_requests(&no_ground_rate, T, false, false)),
            20_000.0,
            "0 = the flight rate on the ground too"
        );
    }

    #[test]
    #[allow(deprecated)]
    fn legacy_requests_come_first_in_whole_hz() {
        let msgs = stream_requests(&rates(), T, true, true);
        assert_eq!(msgs.len(), 13);
        let legacy: Vec<(u8, u16)> = msgs[..4]
            .iter()
            .map(|m| match m {
                MavMessage::REQUEST_DATA_STREAM(r) => {
                    assert_eq!(r.start_stop, 1);
                    (r.req_stream_id as u8, r.req_message_rate)
                }
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(legacy, [(10, 50), (6, 10), (2, 2), (12, 3)]);
        assert!(matches!(msgs[4], MavMessage::COMMAND_LONG(_)));
    }

    #[test]
    fn heartbeat_and_home_request() {
        let MavMessage::HEARTBEAT(h) = heartbeat() else {
            panic!()
        };
        assert_eq!(h.mavtype, MavType::MAV_TYPE_ONBOARD_CONTROLLER);
        assert_eq!(h.autopilot, MavAutopilot::MAV_AUTOPILOT_INVALID);
        let home = request_home(T);
        assert_eq!(home.message_name(), "COMMAND_LONG");
        let MavMessage::COMMAND_LONG(c) = home else {
            panic!()
        };
        assert_eq!(c.command, MavCmd::MAV_CMD_REQUEST_MESSAGE);
        assert_eq!(c.param1, 242.0);
    }
}
