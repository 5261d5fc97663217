//! The pure rules of a flight task (take off to a point, fly to a point): remaining
//! distance and time, and when a task has arrived, failed or been pre-empted.
//! Explicit time; no I/O.

use std::time::{Duration, Instant};

use skymesh_ipc_types::{FlightMode, TaskResult};

use super::link::Snapshot;
use crate::shots::{distance_m, GeoPoint};

/// Speeds below this are treated as this for remaining_time, m/s: a hovering vehicle
/// about to fly does not report "infinite" time.
pub const MIN_SPEED_ESTIMATE_MPS: f64 = 1.0;
/// A failure condition (mode, authority, link, disarm) must hold this long before a
/// task ends: status and authority samples may lag a command just accepted.
pub const FAILURE_DEBOUNCE: Duration = Duration::from_millis(1500);
/// A task progresses while its remaining distance shrinks by at least this.
pub const PROGRESS_STEP_M: f64 = 1.0;
/// Position older than this is not used, seconds.
pub const POSITION_MAX_AGE_NS: u64 = 1_500_000_000;
/// Above this (metres above home, armed) the vehicle counts as flying.
pub const FLYING_ALT_M: f32 = 0.5;

/// The vehicle position (altitude above home) if valid and fresh at `now_ns`.
pub fn position(s: &Snapshot, now_ns: u64) -> Option<GeoPoint> {
    let v = s.state?;
    if v.position_valid == 0 || now_ns.saturating_sub(v.position_stamp_ns) > POSITION_MAX_AGE_NS {
        return None;
    }
    let p = GeoPoint {
        lat_deg: v.lat_deg,
        lon_deg: v.lon_deg,
        alt_rel_m: v.alt_rel_m,
    };
    (p.lat_deg.is_finite() && p.lon_deg.is_finite() && p.alt_rel_m.is_finite()).then_some(p)
}

/// 3-D speed over ground and vertical, m/s.
pub fn speed(s: &Snapshot) -> f64 {
    s.state.map_or(0.0, |v| {
        let [n, e, d] = v.vel_ned_mps.map(f64::from);
        let sp = (n * n + e * e + d * d).sqrt();
        if sp.is_finite() {
            sp
        } else {
            0.0
        }
    })
}

/// Armed and above [`FLYING_ALT_M`].
pub fn is_flying(s: &Snapshot) -> bool {
    let armed = s.status.is_some_and(|st| st.is_armed());
    let alt = s
        .state
        .filter(|v| v.position_valid != 0)
        .map_or(0.0, |v| v.alt_rel_m);
    armed && alt > FLYING_ALT_M
}

/// Distance still to fly: from `at` to `points[0]`, then along the rest, metres.
pub fn remaining_distance(at: &GeoPoint, points: &[GeoPoint]) -> f64 {
    let mut total = 0.0;
    let mut from = *at;
    for p in points {
        total += distance_m(&from, p);
        from = *p;
    }
    total
}

/// `distance / max(speed, MIN_SPEED_ESTIMATE_MPS)`, seconds.
pub fn remaining_time(distance_m: f64, speed_mps: f64) -> f64 {
    let speed = if speed_mps.is_finite() {
        speed_mps.max(MIN_SPEED_ESTIMATE_MPS)
    } else {
        MIN_SPEED_ESTIMATE_MPS
    };
    distance_m.max(0.0) / speed
}

/// What the vehicle says this tick, as a task sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    pub holds_flight: bool,
    pub link_up: bool,
    pub mode: FlightMode,
    pub armed: bool,
    /// Distance to the current leg's end (3-D), `None` without a fresh position.
    pub leg_distance_m: Option<f64>,
    /// Remaining distance of the whole task, for stall detection.
    pub remaining_m: Option<f64>,
}

impl Observation {
    pub fn from_snapshot(s: &Snapshot, leg: Option<f64>, remaining: Option<f64>) -> Self {
        Observation {
            holds_flight: s.holds_flight(),
            link_up: s.status.is_some_and(|st| st.is_link_up()),
            mode: s.status.map_or(FlightMode::Unknown, |st| st.flight_mode()),
            armed: s.status.is_some_and(|st| st.is_armed()),
            leg_distance_m: leg,
            remaining_m: remaining,
        }
    }
}

/// How a task tick ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Continue,
    /// The current leg's end is within the arrival radius.
    Arrived,
    /// Ended without arriving, with this result.
    Failed(TaskResult),
    /// Taken over, with this result (another source took the vehicle).
    Cancelled(TaskResult),
}

/// Watches one task: arrival, and the failure conditions (debounced by
/// [`FAILURE_DEBOUNCE`]) and stalls.
#[derive(Debug, Clone)]
pub struct Monitor {
    arrival_radius_m: f64,
    stall_timeout: Duration,
    /// Since when each failure condition has held.
    since: [Option<Instant>; 5],
    /// Best remaining distance so far and when it last improved by a step.
    best: Option<(f64, Instant)>,
}

const NO_AUTHORITY: usize = 0;
const LINK_DOWN: usize = 1;
const NOT_GUIDED: usize = 2;
const DISARMED: usize = 3;
const NO_POSITION: usize = 4;

impl Monitor {
    pub fn new(arrival_radius_m: f64, stall_timeout: Duration) -> Self {
        Monitor {
            arrival_radius_m,
            stall_timeout,
            since: [None; 5],
            best: None,
        }
    }

    /// A new leg or target: stall detection starts over.
    pub fn restart_progress(&mut self) {
        self.best = None;
    }

    pub fn update(&mut self, o: &Observation, now: Instant) -> Verdict {
        let conditions = [
            !o.holds_flight,
            !o.link_up,
            o.mode != FlightMode::Guided,
            !o.armed,
            o.leg_distance_m.is_none(),
        ];
        for (since, holds) in self.since.iter_mut().zip(conditions) {
            *since = match (*since, holds) {
                (_, false) => None,
                (None, true) => Some(now),
                (s, true) => s,
            };
        }
        let held = |i: usize| {
            self.since[i].is_some_and(|t| now.saturating_duration_since(t) >= FAILURE_DEBOUNCE)
        };
        // Order matters: losing authority to someone else is a pre-emption (cancel);
        // the rest are failures.
        if held(NO_AUTHORITY) {
            return Verdict::Cancelled(TaskResult::NoFlightAuthority);
        }
        if held(LINK_DOWN) {
            return Verdict::Failed(TaskResult::VehicleUnavailable);
        }
        if held(NOT_GUIDED) || held(DISARMED) {
            return Verdict::Failed(TaskResult::WrongState);
        }
        if held(NO_POSITION) {
            return Verdict::Failed(TaskResult::VehicleUnavailable);
        }
        if o.leg_distance_m.is_some_and(|d| d <= self.arrival_radius_m) {
            return Verdict::Arrived;
        }
        if let Some(r) = o.remaining_m {
            match self.best {
                Some((best, _)) if r <= best - PROGRESS_STEP_M => self.best = Some((r, now)),
                Some((_, at)) if now.saturating_duration_since(at) >= self.stall_timeout => {
                    return Verdict::Failed(TaskResult::WrongState);
                }
                Some(_) => {}
                None => self.best = Some((r, now)),
            }
        }
        Verdict::Continue
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shots::offset;
    use skymesh_ipc_types::{AuthorityState, CommandSource, VehicleState, VehicleStatus};

    const HOME: GeoPoint = GeoPoint {
        lat_deg: -35.363_261,
        lon_deg: 149.165_230,
        alt_rel_m: 0.0,
    };

    fn snapshot(alt_rel: f32, armed: bool) -> Snapshot {
        Snapshot {
            state: Some(VehicleState {
                position_valid: 1,
                lat_deg: HOME.lat_deg,
                lon_deg: HOME.lon_deg,
                alt_msl_m: 584.0 + alt_rel,
                alt_rel_m: alt_rel,
                vel_ned_mps: [3.0, 4.0, 0.0],
                position_stamp_ns: 1_000,
                ..Default::default()
            }),
            status: Some(VehicleStatus {
                armed: u8::from(armed),
                link_up: 1,
                mode: FlightMode::Guided.to_wire(),
                ..Default::default()
            }),
            payload: None,
            authority: Some(AuthorityState {
                flight_holder: CommandSource::DjiDrc.to_wire(),
                ..Default::default()
            }),
            source: CommandSource::DjiDrc,
        }
    }

    #[test]
    fn remaining_distance_and_time_follow_the_points() {
        let climb = GeoPoint {
            alt_rel_m: 30.0,
            ..HOME
        };
        let target = GeoPoint {
            alt_rel_m: 30.0,
            ..offset(&HOME, 90.0, 40.0)
        };
        let d = remaining_distance(&HOME, &[climb, target]);
        assert!((d - 70.0).abs() < 0.01, "{d}");
        assert!((remaining_distance(&climb, &[target]) - 40.0).abs() < 0.01);
        assert_eq!(remaining_distance(&target, &[]), 0.0);
        // 5 m/s → 14 s; a hovering vehicle counts as 1 m/s.
        assert!((remaining_time(d, 5.0) - 14.0).abs() < 0.01);
        assert_eq!(remaining_time(d, 0.0), d);
        assert_eq!(remaining_time(d, f64::NAN), d);
        assert_eq!(speed(&snapshot(0.0, true)), 5.0);
    }

    #[test]
    fn flying_needs_armed_and_altitude() {
        assert!(is_flying(&snapshot(10.0, true)));
        assert!(!is_flying(&snapshot(10.0, false)));
        assert!(!is_flying(&snapshot(0.1, true)));
        assert_eq!(
            position(&snapshot(5.0, true), 1_000).unwrap().alt_rel_m,
            5.0
        );
        assert_eq!(
            position(&snapshot(5.0, true), 1_000 + 2_000_000_000),
            None,
            "stale"
        );
    }

    fn obs(s: &Snapshot, leg: f64) -> Observation {
        Observation::from_snapshot(s, Some(leg), Some(leg))
    }

    #[test]
    fn the_monitor_arrives_within_the_radius() {
        let t0 = Instant::now();
        let mut m = Monitor::new(1.5, Duration::from_secs(30));
        let s = snapshot(10.0, true);
        assert_eq!(m.update(&obs(&s, 10.0), t0), Verdict::Continue);
        assert_eq!(m.update(&obs(&s, 1.6), t0), Verdict::Continue);
        assert_eq!(m.update(&obs(&s, 1.5), t0), Verdict::Arrived);
    }

    #[test]
    fn failures_are_debounced_and_classified() {
        let t0 = Instant::now();
        let later = t0 + FAILURE_DEBOUNCE;
        // Pre-emption: another source holds flight authority → cancel.
        let mut s = snapshot(10.0, true);
        s.authority.as_mut().unwrap().flight_holder = CommandSource::ManualRc.to_wire();
        let mut m = Monitor::new(1.5, Duration::from_secs(30));
        assert_eq!(m.update(&obs(&s, 10.0), t0), Verdict::Continue, "may lag");
        assert_eq!(
            m.update(&obs(&s, 10.0), later),
            Verdict::Cancelled(TaskResult::NoFlightAuthority)
        );
        // A mode change (RC switched to LOITER) → failed; a blip is ignored.
        let mut s = snapshot(10.0, true);
        s.status.as_mut().unwrap().mode = FlightMode::Loiter.to_wire();
        let guided = snapshot(10.0, true);
        let mut m = Monitor::new(1.5, Duration::from_secs(30));
        assert_eq!(m.update(&obs(&s, 10.0), t0), Verdict::Continue);
        assert_eq!(
            m.update(&obs(&guided, 10.0), t0 + Duration::from_millis(100)),
            Verdict::Continue
        );
        assert_eq!(
            m.update(&obs(&s, 10.0), later),
            Verdict::Continue,
            "restarted"
        );
        assert_eq!(
            m.update(&obs(&s, 10.0), later + FAILURE_DEBOUNCE),
            Verdict::Failed(TaskResult::WrongState)
        );
        // Link down → vehicle unavailable.
        let mut s = snapshot(10.0, true);
        s.status.as_mut().unwrap().link_up = 0;
        let mut m = Monitor::new(1.5, Duration::from_secs(30));
        m.update(&obs(&s, 10.0), t0);
        assert_eq!(
            m.update(&obs(&s, 10.0), later),
            Verdict::Failed(TaskResult::VehicleUnavailable)
        );
        // Disarmed in flight → wrong state.
        let s = snapshot(10.0, false);
        let mut m = Monitor::new(1.5, Duration::from_secs(30));
        m.update(&obs(&s, 10.0), t0);
        assert_eq!(
            m.update(&obs(&s, 10.0), later),
            Verdict::Failed(TaskResult::WrongState)
        );
        // No position.
        let s = snapshot(10.0, true);
        let mut m = Monitor::new(1.5, Duration::from_secs(30));
        let none = Observation::from_snapshot(&s, None, None);
        m.update(&none, t0);
        assert_eq!(
            m.update(&none, later),
            Verdict::Failed(TaskResult::VehicleUnavailable)
        );
    }

    #[test]
    fn a_stalled_task_fails_and_progress_resets_the_clock() {
        let t0 = Instant::now();
        let stall = Duration::from_secs(10);
        let s = snapshot(10.0, true);
        let mut m = Monitor::new(1.5, stall);
        assert_eq!(m.update(&obs(&s, 100.0), t0), Verdict::Continue);
        assert_eq!(
            m.update(&obs(&s, 99.5), t0 + Duration::from_secs(9)),
            Verdict::Continue
        );
        assert_eq!(
            m.update(&obs(&s, 98.0), t0 + Duration::from_secs(9)),
            Verdict::Continue
        );
        assert_eq!(
            m.update(&obs(&s, 97.5), t0 + Duration::from_secs(18)),
            Verdict::Continue
        );
        assert_eq!(
            m.update(&obs(&s, 97.5), t0 + Duration::from_secs(19)),
            Verdict::Failed(TaskResult::WrongState)
        );
        m.restart_progress();
        assert_eq!(
            m.update(&obs(&s, 97.5), t0 + Duration::from_secs(20)),
            Verdict::Continue
        );
    }
}
