//! Per-link telemetry scheduling: which message ids are due at a given sim
//! time. Rates change with MAV_CMD_SET_MESSAGE_INTERVAL (per message) and
//! REQUEST_DATA_STREAM (per ArduCopter stream group). Pure: time is passed in.

// REQUEST_DATA_STREAM / MAV_DATA_STREAM are deprecated in MAVLink but ArduPilot
// still honours them and many ground stations still send them.
#![allow(deprecated)]

use std::collections::BTreeMap;
use std::time::Duration;

use mavlink::dialects::ardupilotmega::{
    MavDataStream, ATTITUDE_DATA, BATTERY_STATUS_DATA, EKF_STATUS_REPORT_DATA,
    GIMBAL_DEVICE_ATTITUDE_STATUS_DATA, GLOBAL_POSITION_INT_DATA, GOPRO_HEARTBEAT_DATA,
    GPS_RAW_INT_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, SERVO_OUTPUT_RAW_DATA,
    SYS_STATUS_DATA, VFR_HUD_DATA,
};
use mavlink::MessageData;

use crate::config::{StreamDefaults, PHYSICS_HZ};

/// Shortest interval: streams are evaluated once per physics tick.
pub const MIN_INTERVAL: Duration = Duration::from_micros(1_000_000 / PHYSICS_HZ as u64);

/// A SET_MESSAGE_INTERVAL request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IntervalRequest {
    /// -1: stop sending.
    Disable,
    /// 0: back to the default rate.
    Default,
    /// Send every so often (clamped to [`MIN_INTERVAL`]).
    Every(Duration),
}

impl IntervalRequest {
    /// From SET_MESSAGE_INTERVAL param2 (µs); `None` if invalid.
    pub fn from_param(interval_us: f32) -> Option<Self> {
        if interval_us == -1.0 {
            Some(IntervalRequest::Disable)
        } else if interval_us == 0.0 {
            Some(IntervalRequest::Default)
        } else if interval_us > 0.0 && interval_us.is_finite() {
            Some(IntervalRequest::Every(Duration::from_secs_f64(
                f64::from(interval_us) / 1e6,
            )))
        } else {
            None
        }
    }
}

/// ArduCopter's REQUEST_DATA_STREAM groups, restricted to the messages the
/// simulator produces (GCS_MAVLINK_Copter `STREAM_*_msgs`).
pub fn stream_group(stream: MavDataStream) -> &'static [u32] {
    match stream {
        MavDataStream::MAV_DATA_STREAM_EXTENDED_STATUS => {
            &[SYS_STATUS_DATA::ID, GPS_RAW_INT_DATA::ID]
        }
        MavDataStream::MAV_DATA_STREAM_POSITION => {
            &[GLOBAL_POSITION_INT_DATA::ID, LOCAL_POSITION_NED_DATA::ID]
        }
        MavDataStream::MAV_DATA_STREAM_RC_CHANNELS => &[SERVO_OUTPUT_RAW_DATA::ID],
        MavDataStream::MAV_DATA_STREAM_EXTRA1 => &[ATTITUDE_DATA::ID],
        MavDataStream::MAV_DATA_STREAM_EXTRA2 => &[VFR_HUD_DATA::ID],
        MavDataStream::MAV_DATA_STREAM_EXTRA3 => &[
            BATTERY_STATUS_DATA::ID,
            EKF_STATUS_REPORT_DATA::ID,
            GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID,
        ],
        MavDataStream::MAV_DATA_STREAM_ALL => &[
            SYS_STATUS_DATA::ID,
            GPS_RAW_INT_DATA::ID,
            GLOBAL_POSITION_INT_DATA::ID,
            LOCAL_POSITION_NED_DATA::ID,
            ATTITUDE_DATA::ID,
            VFR_HUD_DATA::ID,
            BATTERY_STATUS_DATA::ID,
            EKF_STATUS_REPORT_DATA::ID,
            GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID,
            SERVO_OUTPUT_RAW_DATA::ID,
        ],
        // RAW_SENSORS, RAW_CONTROLLER: nothing the sim produces.
        _ => &[],
    }
}

#[derive(Debug, Clone, Copy)]
struct Stream {
    interval: Option<Duration>,
    next_due: Duration,
}

/// The schedule of one link.
#[derive(Debug, Clone)]
pub struct StreamScheduler {
    defaults: BTreeMap<u32, Option<Duration>>,
    streams: BTreeMap<u32, Stream>,
}

impl StreamScheduler {
    /// Default rates: HEARTBEAT 1 Hz, ATTITUDE, the gimbal attitude, the servo
    /// outputs, the GoPro heartbeat and the rest from `defaults`; everything due at
    /// `now` so a new link hears a heartbeat at once.
    pub fn new(defaults: &StreamDefaults, now: Duration) -> Self {
        let mut d = BTreeMap::new();
        d.insert(HEARTBEAT_DATA::ID, Some(Duration::from_secs(1)));
        for id in stream_group(MavDataStream::MAV_DATA_STREAM_ALL) {
            d.insert(*id, defaults.telemetry);
        }
        d.insert(ATTITUDE_DATA::ID, defaults.attitude);
        d.insert(
            GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID,
            defaults.gimbal_attitude,
        );
        d.insert(SERVO_OUTPUT_RAW_DATA::ID, defaults.servo_output);
        d.insert(GOPRO_HEARTBEAT_DATA::ID, defaults.gopro_heartbeat);
        let streams = d
            .iter()
            .map(|(id, interval)| {
                (
                    *id,
                    Stream {
                        interval: *interval,
                        next_due: now,
                    },
                )
            })
            .collect();
        Self {
            defaults: d,
            streams,
        }
    }

    /// Apply a SET_MESSAGE_INTERVAL for message `id` (the caller checked the
    /// simulator can produce it).
    pub fn set_interval(&mut self, id: u32, req: IntervalRequest, now: Duration) {
        let interval = match req {
            IntervalRequest::Disable => None,
            IntervalRequest::Default => self.defaults.get(&id).copied().flatten(),
            IntervalRequest::Every(d) => Some(d.max(MIN_INTERVAL)),
        };
        // The new rate starts on its grid (see [`next_on_grid`]), so streams of
        // commensurate rates fall due on the same ticks however their requests
        // were spread.
        let next_due = interval.map_or(now, |i| {
            if on_grid(now, i) {
                now
            } else {
                next_on_grid(now, i)
            }
        });
        self.streams.insert(id, Stream { interval, next_due });
    }

    /// Apply a REQUEST_DATA_STREAM (rate 0 or `start == false` stops the group).
    pub fn request_data_stream(
        &mut self,
        stream: MavDataStream,
        rate_hz: u16,
        start: bool,
        now: Duration,
    ) {
        let req = if start && rate_hz > 0 {
            IntervalRequest::Every(Duration::from_secs_f64(1.0 / f64::from(rate_hz)))
        } else {
            IntervalRequest::Disable
        };
        for id in stream_group(stream) {
            self.set_interval(*id, req, now);
        }
    }

    /// Current interval of message `id` (`None` = not streamed).
    pub fn interval(&self, id: u32) -> Option<Duration> {
        self.streams.get(&id).and_then(|s| s.interval)
    }

    /// When the next message falls due (`None`: nothing is streamed).
    pub fn next_due(&self) -> Option<Duration> {
        self.streams
            .values()
            .filter(|s| s.interval.is_some())
            .map(|s| s.next_due)
            .min()
    }

    /// Message ids due at `now`, in id order (HEARTBEAT first).
    pub fn due(&mut self, now: Duration) -> Vec<u32> {
        let mut out = Vec::new();
        self.due_into(now, &mut out);
        out
    }

    /// [`Self::due`] into `out` (cleared first), so a caller can reuse one buffer.
    pub fn due_into(&mut self, now: Duration, out: &mut Vec<u32>) {
        out.clear();
        for (id, s) in &mut self.streams {
            let Some(interval) = s.interval else { continue };
            if now >= s.next_due {
                out.push(*id);
                // The next multiple of the interval in sim time: the long-run rate
                // stays exact, a stall never bursts, and every stream whose
                // interval divides another's is due on the same ticks as it —
                // one batch of frames per tick instead of one per stream's phase
                // (the link's reader wakes once: 50 a second for the usual
                // 50/10/5/2 Hz set, not ~90).
                s.next_due = next_on_grid(now, interval);
            }
        }
    }
}

/// The first multiple of `interval` (counted from sim time zero) after `now`.
fn next_on_grid(now: Duration, interval: Duration) -> Duration {
    let i = interval.as_nanos().max(1);
    let next = (now.as_nanos() / i + 1) * i;
    Duration::from_nanos(u64::try_from(next).unwrap_or(u64::MAX))
}

fn on_grid(now: Duration, interval: Duration) -> bool {
    now.as_nanos().is_multiple_of(interval.as_nanos().max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn defaults() -> StreamDefaults {
        StreamDefaults {
            attitude: Some(Duration::from_millis(100)),
            telemetry: Some(Duration::from_secs(1)),
            gimbal_attitude: Some(Duration::from_millis(100)),
            servo_output: Some(Duration::from_millis(500)),
            gopro_heartbeat: Some(Duration::from_secs(1)),
        }
    }

    /// Count emissions of `id` over `secs` of 10 ms ticks.
    fn count(s: &mut StreamScheduler, id: u32, from: Duration, secs: u64) -> usize {
        let mut n = 0;
        for tick in 0..secs * 100 {
            let now = from + Duration::from_millis(10 * tick);
            n += s.due(now).iter().filter(|x| **x == id).count();
        }
        n
    }

    #[test]
    fn defaults_heartbeat_first_and_rates() {
        let mut s = StreamScheduler::new(&defaults(), Duration::ZERO);
        assert_eq!(s.due(Duration::ZERO)[0], HEARTBEAT_DATA::ID);
        let mut s = StreamScheduler::new(&defaults(), Duration::ZERO);
        assert_eq!(
            count(&mut s.clone(), HEARTBEAT_DATA::ID, Duration::ZERO, 10),
            10
        );
        assert_eq!(count(&mut s, ATTITUDE_DATA::ID, Duration::ZERO, 10), 100);
    }

    #[test]
    fn set_interval_100hz_disable_and_default() {
        let mut s = StreamScheduler::new(&defaults(), Duration::ZERO);
        let id = ATTITUDE_DATA::ID;
        s.set_interval(
            id,
            IntervalRequest::Every(Duration::from_micros(10_000)),
            Duration::ZERO,
        );
        assert_eq!(count(&mut s, id, Duration::ZERO, 1), 100);
        // Faster than the physics tick is clamped to it.
        s.set_interval(
            id,
            IntervalRequest::Every(Duration::from_micros(100)),
            Duration::ZERO,
        );
        assert_eq!(s.interval(id), Some(MIN_INTERVAL));
        s.set_interval(id, IntervalRequest::Disable, Duration::ZERO);
        assert_eq!(count(&mut s, id, Duration::ZERO, 1), 0);
        s.set_interval(id, IntervalRequest::Default, Duration::ZERO);
        assert_eq!(s.interval(id), Some(Duration::from_millis(100)));
    }

    #[test]
    fn odd_rates_average_out() {
        let mut s = StreamScheduler::new(&defaults(), Duration::ZERO);
        let id = VFR_HUD_DATA::ID;
        s.set_interval(
            id,
            IntervalRequest::Every(Duration::from_secs_f64(1.0 / 30.0)),
            Duration::ZERO,
        );
        let n = count(&mut s, id, Duration::ZERO, 10);
        assert!((298..=301).contains(&n), "{n}");
    }

    #[test]
    fn data_stream_groups() {
        let mut s = StreamScheduler::new(&defaults(), Duration::ZERO);
        s.request_data_stream(
            MavDataStream::MAV_DATA_STREAM_POSITION,
            4,
            true,
            Duration::ZERO,
        );
        assert_eq!(
            s.interval(GLOBAL_POSITION_INT_DATA::ID),
            Some(Duration::from_millis(250))
        );
        s.request_data_stream(
            MavDataStream::MAV_DATA_STREAM_ALL,
            10,
            false,
            Duration::ZERO,
        );
        assert_eq!(s.interval(ATTITUDE_DATA::ID), None);
        assert_eq!(s.interval(HEARTBEAT_DATA::ID), Some(Duration::from_secs(1)));
    }

    #[test]
    fn interval_params() {
        assert_eq!(
            IntervalRequest::from_param(-1.0),
            Some(IntervalRequest::Disable)
        );
        assert_eq!(
            IntervalRequest::from_param(0.0),
            Some(IntervalRequest::Default)
        );
        assert_eq!(IntervalRequest::from_param(-5.0), None);
        assert_eq!(IntervalRequest::from_param(f32::NAN), None);
        assert_eq!(
            IntervalRequest::from_param(10_000.0),
            Some(IntervalRequest::Every(Duration::from_millis(10)))
        );
    }

    #[test]
    fn gimbal_attitude_and_gopro_heartbeat_defaults() {
        let mut s = StreamScheduler::new(&defaults(), Duration::ZERO);
        let gimbal = GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID;
        assert_eq!(count(&mut s.clone(), gimbal, Duration::ZERO, 10), 100);
        assert_eq!(
            count(&mut s.clone(), GOPRO_HEARTBEAT_DATA::ID, Duration::ZERO, 10),
            10
        );
        s.set_interval(
            gimbal,
            IntervalRequest::Every(Duration::from_millis(50)),
            Duration::ZERO,
        );
        assert_eq!(count(&mut s, gimbal, Duration::ZERO, 2), 40);
        let no_gopro = StreamDefaults {
            gopro_heartbeat: None,
            ..defaults()
        };
        let mut s = StreamScheduler::new(&no_gopro, Duration::ZERO);
        assert_eq!(
            count(&mut s, GOPRO_HEARTBEAT_DATA::ID, Duration::ZERO, 5),
            0
        );
    }

    #[test]
    fn servo_output_has_its_own_default_and_is_in_the_rc_channels_group() {
        let mut s = StreamScheduler::new(&defaults(), Duration::ZERO);
        let id = SERVO_OUTPUT_RAW_DATA::ID;
        assert_eq!(count(&mut s.clone(), id, Duration::ZERO, 10), 20, "2 Hz");
        s.request_data_stream(
            MavDataStream::MAV_DATA_STREAM_RC_CHANNELS,
            10,
            true,
            Duration::ZERO,
        );
        assert_eq!(s.interval(id), Some(Duration::from_millis(100)));
        assert_eq!(
            s.interval(ATTITUDE_DATA::ID),
            Some(Duration::from_millis(100)),
            "only the group's messages change"
        );
        s.request_data_stream(MavDataStream::MAV_DATA_STREAM_ALL, 0, false, Duration::ZERO);
        assert_eq!(s.interval(id), None);
        s.set_interval(id, IntervalRequest::Default, Duration::ZERO);
        assert_eq!(s.interval(id), Some(Duration::from_millis(500)));
        let off = StreamDefaults {
            servo_output: None,
            ..defaults()
        };
        let mut s = StreamScheduler::new(&off, Duration::ZERO);
        assert_eq!(count(&mut s, id, Duration::ZERO, 5), 0);
    }

    #[test]
    fn commensurate_streams_fall_due_on_the_same_ticks_whenever_requested() {
        let mut s = StreamScheduler::new(&defaults(), Duration::ZERO);
        s.request_data_stream(MavDataStream::MAV_DATA_STREAM_ALL, 0, false, Duration::ZERO);
        // Requested on three different ticks, as a link's requests arrive.
        let ms = Duration::from_millis;
        s.set_interval(ATTITUDE_DATA::ID, IntervalRequest::Every(ms(20)), ms(30));
        s.set_interval(
            GLOBAL_POSITION_INT_DATA::ID,
            IntervalRequest::Every(ms(100)),
            ms(40),
        );
        s.set_interval(SYS_STATUS_DATA::ID, IntervalRequest::Every(ms(500)), ms(70));
        let mut ticks_with_frames = 0;
        let (mut attitude, mut position, mut status) = (0, 0, 0);
        for tick in 8..108 {
            let now = ms(10 * tick);
            let due: Vec<u32> = s
                .due(now)
                .into_iter()
                .filter(|id| *id != HEARTBEAT_DATA::ID)
                .collect();
            if due.is_empty() {
                continue;
            }
            ticks_with_frames += 1;
            assert!(
                due.contains(&ATTITUDE_DATA::ID),
                "at {now:?} {due:?} fell due off the 20 ms grid"
            );
            attitude += 1;
            position += usize::from(due.contains(&GLOBAL_POSITION_INT_DATA::ID));
            status += usize::from(due.contains(&SYS_STATUS_DATA::ID));
        }
        // One second (80..1080 ms): 50, 10 and 2 of them, on 50 ticks.
        assert_eq!(
            (ticks_with_frames, attitude, position, status),
            (50, 50, 10, 2)
        );
    }

    #[test]
    fn a_stall_does_not_burst() {
        let mut s = StreamScheduler::new(&defaults(), Duration::ZERO);
        s.due(Duration::ZERO);
        let due = s.due(Duration::from_secs(5));
        assert_eq!(due.iter().filter(|x| **x == ATTITUDE_DATA::ID).count(), 1);
    }
}
