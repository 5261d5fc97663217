//! The pure rules of a flight task (takeoff_to_point, fly_to_point): heights,
//! remaining distance and time, the planned path, and when a task has arrived,
//! failed or been pre-empted. Explicit time; no I/O.
//!
//! Heights: DJI sends ellipsoid heights (WGS-84); MAVLink `GoTo` takes metres above
//! home. `rel = ellipsoid − geoid_undulation − home_msl`, where `home_msl` is the
//! vehicle's home altitude above mean sea level (`VehicleStatus`, else derived from
//! `VehicleState`: `alt_msl − alt_rel`) and `geoid_undulation` the vehicle's own
//! (GPS_RAW_INT `alt_ellipsoid − alt`, `VehicleState::geoid_undulation_m`); the
//! configured `[flight] geoid_undulation_m` only while the autopilot reports none.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use dji_proto::{codes, PathPoint};
use skymesh_ipc_types::FlightMode;
use skymesh_shot_engine::shots::{distance_m, GeoPoint};

use crate::link::Snapshot;

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

/// Converts between DJI ellipsoid heights and heights above home.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Heights {
    /// Home altitude above mean sea level, m.
    pub home_msl_m: f64,
    /// Ellipsoid − MSL, m.
    pub undulation_m: f64,
}

/// Ellipsoid − MSL where the vehicle is: the autopilot's (`alt_ellipsoid_valid`),
/// else `fallback_m` (the configured value; logged once per process).
pub fn undulation(s: &Snapshot, fallback_m: f64) -> f64 {
    static FALLBACK_LOGGED: AtomicBool = AtomicBool::new(false);
    match s.state {
        Some(v) if v.alt_ellipsoid_valid != 0 && v.geoid_undulation_m.is_finite() => {
            f64::from(v.geoid_undulation_m)
        }
        _ => {
            if !FALLBACK_LOGGED.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    geoid_undulation_m = fallback_m,
                    "the autopilot reports no ellipsoid altitude: DJI heights use the configured geoid undulation"
                );
            }
            fallback_m
        }
    }
}

impl Heights {
    /// From the latest samples; `None` without a home or a position. The undulation
    /// is the vehicle's, else `fallback_undulation_m` (see [`undulation`]).
    pub fn from_snapshot(s: &Snapshot, fallback_undulation_m: f64) -> Option<Heights> {
        let home = match (s.status, s.state) {
            (Some(st), _) if st.home_valid != 0 && st.home_alt_msl_m.is_finite() => {
                f64::from(st.home_alt_msl_m)
            }
            (_, Some(v)) if v.position_valid != 0 => {
                f64::from(v.alt_msl_m) - f64::from(v.alt_rel_m)
            }
            _ => return None,
        };
        home.is_finite().then(|| Heights {
            home_msl_m: home,
            undulation_m: undulation(s, fallback_undulation_m),
        })
    }

    pub fn rel_from_ellipsoid(&self, h: f64) -> f64 {
        h - self.undulation_m - self.home_msl_m
    }

    pub fn ellipsoid_from_rel(&self, rel: f64) -> f64 {
        rel + self.home_msl_m + self.undulation_m
    }
}

/// One decimal (the document's `step: 0.1`).
pub fn round1(x: f64) -> f64 {
    if x.is_finite() {
        (x * 10.0).round() / 10.0
    } else {
        0.0
    }
}

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

/// The points still to fly as the document's trajectory points (ellipsoid heights,
/// 6 decimals of a degree, 0.1 m).
pub fn path_points(points: &[GeoPoint], h: &Heights) -> Vec<PathPoint> {
    let deg6 = |x: f64| (x * 1e6).round() / 1e6;
    points
        .iter()
        .map(|p| PathPoint {
            latitude: deg6(p.lat_deg),
            longitude: deg6(p.lon_deg),
            height: round1(h.ellipsoid_from_rel(f64::from(p.alt_rel_m))),
        })
        .collect()
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
    /// `wayline_failed` with this result.
    Failed(u32),
    /// `wayline_cancel` with this result (another source took the vehicle).
    Cancelled(u32),
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
            return Verdict::Cancelled(codes::FLIGHT_AUTHORITY_REQUIRED);
        }
        if held(LINK_DOWN) {
            return Verdict::Failed(codes::VEHICLE_UNAVAILABLE);
        }
        if held(NOT_GUIDED) || held(DISARMED) {
            return Verdict::Failed(codes::WRONG_STATE);
        }
        if held(NO_POSITION) {
            return Verdict::Failed(codes::VEHICLE_UNAVAILABLE);
        }
        if o.leg_distance_m.is_some_and(|d| d <= self.arrival_radius_m) {
            return Verdict::Arrived;
        }
        if let Some(r) = o.remaining_m {
            match self.best {
                Some((best, _)) if r <= best - PROGRESS_STEP_M => self.best = Some((r, now)),
                Some((_, at)) if now.saturating_duration_since(at) >= self.stall_timeout => {
                    return Verdict::Failed(codes::WRONG_STATE);
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
    use skymesh_ipc_types::{AuthorityState, CommandSource, VehicleState, VehicleStatus};
    use skymesh_shot_engine::shots::offset;

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
        }
    }

    #[test]
    fn heights_convert_between_ellipsoid_and_home_relative() {
        let mut s = snapshot(10.0, true);
        let h = Heights::from_snapshot(&s, 20.0).unwrap();
        assert_eq!(h.home_msl_m, 584.0, "derived from the state without a home");
        assert_eq!(h.rel_from_ellipsoid(654.0), 50.0);
        assert_eq!(h.ellipsoid_from_rel(50.0), 654.0);
        let st = s.status.as_mut().unwrap();
        st.home_valid = 1;
        st.home_alt_msl_m = 600.0;
        assert_eq!(Heights::from_snapshot(&s, 0.0).unwrap().home_msl_m, 600.0);
        assert_eq!(Heights::from_snapshot(&Snapshot::default(), 0.0), None);
        // The autopilot's undulation wins over the configured one.
        let v = s.state.as_mut().unwrap();
        v.alt_ellipsoid_valid = 1;
        v.geoid_undulation_m = 19.5;
        let h = Heights::from_snapshot(&s, 20.0).unwrap();
        assert_eq!(h.undulation_m, 19.5);
        assert_eq!(h.rel_from_ellipsoid(669.5), 50.0);
        // A flag without a value falls back.
        s.state.as_mut().unwrap().geoid_undulation_m = f32::NAN;
        assert_eq!(Heights::from_snapshot(&s, 20.0).unwrap().undulation_m, 20.0);
    }

    #[test]
    fn remaining_distance_time_and_path_follow_the_points() {
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
        assert_eq!(round1(remaining_time(d, 5.0)), 14.0);
        assert_eq!(round1(remaining_time(d, 0.0)), round1(d));
        assert_eq!(remaining_time(d, f64::NAN), d);
        assert_eq!(round1(12.345), 12.3);
        assert_eq!(round1(f64::INFINITY), 0.0);
        assert_eq!(speed(&snapshot(0.0, true)), 5.0);
        let h = Heights {
            home_msl_m: 584.0,
            undulation_m: 10.0,
        };
        let pts = path_points(&[climb, target], &h);
        assert_eq!(pts.len(), 2);
        assert_eq!(pts[0].height, 624.0);
        assert_eq!(pts[0].latitude, -35.363261);
        assert!((pts[1].longitude - target.lon_deg).abs() < 1e-6);
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
            Verdict::Cancelled(codes::FLIGHT_AUTHORITY_REQUIRED)
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
            Verdict::Failed(codes::WRONG_STATE)
        );
        // Link down → vehicle unavailable.
        let mut s = snapshot(10.0, true);
        s.status.as_mut().unwrap().link_up = 0;
        let mut m = Monitor::new(1.5, Duration::from_secs(30));
        m.update(&obs(&s, 10.0), t0);
        assert_eq!(
            m.update(&obs(&s, 10.0), later),
            Verdict::Failed(codes::VEHICLE_UNAVAILABLE)
        );
        // Disarmed in flight → wrong state.
        let s = snapshot(10.0, false);
        let mut m = Monitor::new(1.5, Duration::from_secs(30));
        m.update(&obs(&s, 10.0), t0);
        assert_eq!(
            m.update(&obs(&s, 10.0), later),
            Verdict::Failed(codes::WRONG_STATE)
        );
        // No position.
        let s = snapshot(10.0, true);
        let mut m = Monitor::new(1.5, Duration::from_secs(30));
        let none = Observation::from_snapshot(&s, None, None);
        m.update(&none, t0);
        assert_eq!(
            m.update(&none, later),
            Verdict::Failed(codes::VEHICLE_UNAVAILABLE)
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
            Verdict::Failed(codes::WRONG_STATE)
        );
        m.restart_progress();
        assert_eq!(
            m.update(&obs(&s, 97.5), t0 + Duration::from_secs(20)),
            Verdict::Continue
        );
    }
}
