//! Panorama sweep, pure: the station plan, the order of the steps and the
//! progress they report. [`super::pano_task`] runs it against the vehicle.
//!
//! The gimbal turns (payload authority only: the aircraft does not move) through
//! the stations and the camera takes one photo at each.
//!
//! **Station plan.** `n` stations (the request's `pano_stations`) spread evenly over
//! the full circle, `360/n`° apart in yaw at pitch `pano_pitch_deg`, the first at
//! the gimbal's yaw when the sweep starts. Yaws are relative to the nose and wrapped
//! into the mount's travel (−180°, 180°]; a mount cannot turn through its back, so
//! the stations are visited as a sweep: clockwise from the start up to the last one
//! before the back, then counter-clockwise through the rest. Afterwards the gimbal
//! returns to where it started (pitch and yaw).
//!
//! **Steps.** At each station: `Gimbal` to it, wait until `PayloadState` shows the
//! gimbal within [`SETTLE_TOLERANCE_DEG`] (in pitch and in yaw), `CameraCapture`
//! (acknowledged), then a progress event. Close to straight down
//! ([`YAW_UNOBSERVABLE_BELOW_DEG`]) the gimbal's yaw cannot be observed: only the
//! pitch is compared there.
//!
//! **Progress.** Each capture is one step and the return to the start the last:
//! after `k` of `n` captures `percent = ⌊100·k / (n + 1)⌋` (0 before the first);
//! only the end (`Done`) reports 100. Nothing is stitched: the `n` photos stay on
//! the camera.

use skymesh_ipc_types::task::PanoTaskStatus;
use skymesh_ipc_types::{Command, TaskEvent, TaskEventKind, TaskRequest, TaskResult};
use skymesh_runtime::angle::wrap_180_upper as wrap180;

/// Gimbal pitch is clamped to this range, degrees (down negative).
pub const GIMBAL_PITCH_RANGE: (f64, f64) = (-90.0, 30.0);
/// The gimbal has reached a station when within this many degrees of it.
pub const SETTLE_TOLERANCE_DEG: f64 = 2.0;
/// Below this pitch (degrees, down negative) the gimbal's yaw is not observable
/// (the attitude's Euler angles degenerate at straight down): only pitch counts.
pub const YAW_UNOBSERVABLE_BELOW_DEG: f64 = -85.0;

/// Where the gimbal points: pitch (down negative) and yaw relative to the nose
/// (clockwise positive), degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aim {
    pub pitch_deg: f64,
    pub yaw_deg: f64,
}

impl Aim {
    /// The bus command that turns the gimbal here.
    pub fn command(&self) -> Command {
        Command::Gimbal {
            pitch_deg: self
                .pitch_deg
                .clamp(GIMBAL_PITCH_RANGE.0, GIMBAL_PITCH_RANGE.1) as f32,
            yaw_deg: wrap180(self.yaw_deg) as f32,
        }
    }

    /// True when a gimbal at `pitch`, `yaw` is within `tol` degrees of this aim (yaw
    /// compared around the circle; not at all near straight down).
    pub fn reached_by(&self, pitch: f64, yaw: f64, tol: f64) -> bool {
        let pitch_ok = (pitch - self.pitch_deg).abs() <= tol;
        let yaw_ok =
            self.pitch_deg < YAW_UNOBSERVABLE_BELOW_DEG || wrap180(yaw - self.yaw_deg).abs() <= tol;
        pitch_ok && yaw_ok
    }
}

/// The `n` stations of a panorama starting at yaw `start_yaw_deg`, in the order they
/// are visited (see the module docs). `n` ≥ 1.
pub fn stations(start_yaw_deg: f64, n: usize, pitch_deg: f64) -> Vec<Aim> {
    let step = 360.0 / n.max(1) as f64;
    let first = wrap180(start_yaw_deg);
    let mut yaws: Vec<f64> = (0..n.max(1))
        .map(|i| wrap180(start_yaw_deg + i as f64 * step))
        .collect();
    yaws.sort_by(f64::total_cmp);
    // Clockwise from the start (inclusive), then back counter-clockwise.
    let (mut ccw, cw): (Vec<f64>, Vec<f64>) = yaws.into_iter().partition(|y| *y < first);
    ccw.reverse();
    cw.into_iter()
        .chain(ccw)
        .map(|yaw_deg| Aim { pitch_deg, yaw_deg })
        .collect()
}

/// Percent done after `captured` of `stations` photos: the return to the start is
/// the last step, so only the end reports 100.
pub fn percent(captured: usize, stations: usize) -> u8 {
    let p = captured.min(stations) * 100 / (stations + 1);
    p.min(99) as u8
}

/// What the panorama is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Turning to station `i` (0-based) and waiting for the gimbal to get there.
    Aiming(usize),
    /// At station `i`: taking its photo.
    Capturing(usize),
    /// Every photo taken: turning back to where the gimbal started.
    Returning,
    /// Back at the start.
    Done,
}

/// One panorama: its stations, where it started and how far it got.
#[derive(Debug, Clone, PartialEq)]
pub struct Panorama {
    start: Aim,
    stations: Vec<Aim>,
    stage: Stage,
}

impl Panorama {
    /// A panorama from the gimbal at `start`: `n` stations at `pitch_deg`.
    pub fn new(start: Aim, n: usize, pitch_deg: f64) -> Self {
        Panorama {
            start,
            stations: stations(start.yaw_deg, n, pitch_deg),
            stage: Stage::Aiming(0),
        }
    }

    pub fn stage(&self) -> Stage {
        self.stage
    }

    pub fn start(&self) -> Aim {
        self.start
    }

    pub fn stations(&self) -> &[Aim] {
        &self.stations
    }

    /// Where the gimbal must be for the current stage (`None` once done).
    pub fn target(&self) -> Option<Aim> {
        match self.stage {
            Stage::Aiming(i) | Stage::Capturing(i) => self.stations.get(i).copied(),
            Stage::Returning => Some(self.start),
            Stage::Done => None,
        }
    }

    /// Photos taken so far.
    pub fn captured(&self) -> usize {
        match self.stage {
            Stage::Aiming(i) | Stage::Capturing(i) => i,
            Stage::Returning | Stage::Done => self.stations.len(),
        }
    }

    pub fn percent(&self) -> u8 {
        match self.stage {
            Stage::Done => 100,
            _ => percent(self.captured(), self.stations.len()),
        }
    }

    /// The gimbal reached the target: a station's photo is next, or the panorama
    /// is done. No effect in the other stages.
    pub fn on_settled(&mut self) {
        self.stage = match self.stage {
            Stage::Aiming(i) => Stage::Capturing(i),
            Stage::Returning => Stage::Done,
            other => other,
        };
    }

    /// The current station's photo was taken: the next station, or back to the
    /// start after the last. No effect in the other stages.
    pub fn on_captured(&mut self) {
        self.stage = match self.stage {
            Stage::Capturing(i) if i + 1 < self.stations.len() => Stage::Aiming(i + 1),
            Stage::Capturing(_) => Stage::Returning,
            other => other,
        };
    }

    /// The Pano event for `request`: `status` with `result`, the photos taken and
    /// the percent reached (100 only when `Done`).
    pub fn event(
        &self,
        request: &TaskRequest,
        status: PanoTaskStatus,
        result: TaskResult,
    ) -> TaskEvent {
        let percent = match status {
            PanoTaskStatus::Done => 100,
            _ => self.percent(),
        };
        let u8_of = |n: usize| u8::try_from(n).unwrap_or(u8::MAX);
        TaskEvent {
            kind: TaskEventKind::Pano.to_wire(),
            status: status.to_wire(),
            pano_photos: u8_of(self.captured()),
            pano_stations: u8_of(self.stations.len()),
            pano_percent: percent,
            ..TaskEvent::reply(request, result)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn yaws(s: &[Aim]) -> Vec<f64> {
        s.iter()
            .map(|a| (a.yaw_deg * 10.0).round() / 10.0)
            .collect()
    }

    #[test]
    fn eight_stations_sweep_clockwise_then_back() {
        let s = stations(0.0, 8, 0.0);
        assert_eq!(
            yaws(&s),
            [0.0, 45.0, 90.0, 135.0, 180.0, -45.0, -90.0, -135.0]
        );
        assert!(s.iter().all(|a| a.pitch_deg == 0.0));
        // Started a little left of the nose: the station behind is −179.7 and is
        // reached counter-clockwise, never through the mount's back.
        let s = stations(0.3, 8, -10.0);
        assert_eq!(
            yaws(&s),
            [0.3, 45.3, 90.3, 135.3, -44.7, -89.7, -134.7, -179.7]
        );
        assert!(s.iter().all(|a| a.pitch_deg == -10.0));
        // Every leg stays inside (−180, 180]: consecutive yaws never jump by more than
        // a sweep can turn without crossing the back.
        for start in [-180.0, -179.0, -100.0, -0.3, 0.0, 10.0, 170.0, 180.0] {
            let s = stations(start, 8, 0.0);
            assert_eq!(s.len(), 8);
            assert!((s[0].yaw_deg - wrap180(start)).abs() < 1e-9, "{start}");
            for a in &s {
                assert!(a.yaw_deg > -180.0 && a.yaw_deg <= 180.0, "{start}: {a:?}");
            }
            let mut sorted = yaws(&s);
            sorted.sort_by(f64::total_cmp);
            for w in sorted.windows(2) {
                assert!((w[1] - w[0] - 45.0).abs() < 0.11, "{start}: {sorted:?}");
            }
            // Clockwise first (increasing), then counter-clockwise (decreasing).
            let turn = s.windows(2).position(|w| w[1].yaw_deg < w[0].yaw_deg);
            if let Some(t) = turn {
                assert!(
                    s[t + 1..].windows(2).all(|w| w[1].yaw_deg < w[0].yaw_deg),
                    "{start}: {:?}",
                    yaws(&s)
                );
            }
        }
    }

    #[test]
    fn other_station_counts() {
        assert_eq!(yaws(&stations(0.0, 4, 0.0)), [0.0, 90.0, 180.0, -90.0]);
        assert_eq!(yaws(&stations(90.0, 3, 0.0)), [90.0, -30.0, -150.0]);
        assert_eq!(stations(0.0, 12, 0.0).len(), 12);
    }

    #[test]
    fn percent_rises_and_only_the_end_is_100() {
        let seq: Vec<u8> = (0..=8).map(|k| percent(k, 8)).collect();
        assert_eq!(seq, [0, 11, 22, 33, 44, 55, 66, 77, 88]);
        assert_eq!(percent(2, 2), 66);
        assert_eq!(percent(99, 2), 66, "never past the photos");
    }

    #[test]
    fn stages_go_station_by_station_then_return() {
        let start = Aim {
            pitch_deg: -30.0,
            yaw_deg: 10.0,
        };
        let mut p = Panorama::new(start, 3, 0.0);
        assert_eq!(p.stage(), Stage::Aiming(0));
        assert_eq!(p.target(), Some(p.stations()[0]));
        // Out-of-order events change nothing.
        p.on_captured();
        assert_eq!(p.stage(), Stage::Aiming(0));
        let mut seen = Vec::new();
        for i in 0..3 {
            p.on_settled();
            assert_eq!(p.stage(), Stage::Capturing(i));
            p.on_settled();
            assert_eq!(p.stage(), Stage::Capturing(i), "settled twice");
            seen.push(p.target().unwrap());
            p.on_captured();
            assert_eq!(p.captured(), i + 1);
        }
        assert_eq!(seen, p.stations());
        assert_eq!(p.stage(), Stage::Returning);
        assert_eq!(p.target(), Some(start));
        assert_eq!(p.percent(), 75);
        p.on_captured();
        assert_eq!(p.stage(), Stage::Returning);
        p.on_settled();
        assert_eq!(p.stage(), Stage::Done);
        assert_eq!((p.target(), p.percent()), (None, 100));
    }

    #[test]
    fn events_carry_photos_percent_and_result() {
        let req = TaskRequest {
            request_id: 4,
            vehicle_id: 1,
            source: skymesh_ipc_types::CommandSource::DjiDrc.to_wire(),
            ..Default::default()
        };
        let mut p = Panorama::new(
            Aim {
                pitch_deg: 0.0,
                yaw_deg: 0.0,
            },
            8,
            0.0,
        );
        let e = p.event(&req, PanoTaskStatus::InProgress, TaskResult::Ok);
        assert_eq!((e.pano_photos, e.pano_stations, e.pano_percent), (0, 8, 0));
        assert_eq!(e.kind(), Ok(TaskEventKind::Pano));
        assert_eq!((e.request_id, e.vehicle_id, e.source), (4, 1, req.source));
        p.on_settled();
        p.on_captured();
        let e = p.event(&req, PanoTaskStatus::InProgress, TaskResult::Ok);
        assert_eq!((e.pano_photos, e.pano_percent), (1, 11));
        assert_eq!(e.pano_status(), Ok(PanoTaskStatus::InProgress));
        let e = p.event(&req, PanoTaskStatus::Failed, TaskResult::WrongState);
        assert_eq!(e.result(), Ok(TaskResult::WrongState));
        assert_eq!(e.pano_percent, 11, "a failure reports where it got");
        let e = p.event(&req, PanoTaskStatus::Done, TaskResult::Ok);
        assert_eq!(e.pano_percent, 100);
    }

    #[test]
    fn reached_compares_around_the_circle() {
        let a = Aim {
            pitch_deg: 0.0,
            yaw_deg: 180.0,
        };
        assert!(a.reached_by(1.0, -179.0, 2.0));
        assert!(a.reached_by(-1.9, 178.5, 2.0));
        assert!(!a.reached_by(2.5, 180.0, 2.0));
        assert!(!a.reached_by(0.0, 177.0, 2.0));
        // Straight down: the yaw cannot be seen, only the pitch counts.
        let down = Aim {
            pitch_deg: -90.0,
            yaw_deg: 40.0,
        };
        assert!(down.reached_by(-89.0, -120.0, 2.0));
        assert!(!down.reached_by(-80.0, 40.0, 2.0));
        assert_eq!(
            Aim {
                pitch_deg: -120.0,
                yaw_deg: 190.0
            }
            .command(),
            Command::Gimbal {
                pitch_deg: -90.0,
                yaw_deg: -170.0
            }
        );
    }
}
