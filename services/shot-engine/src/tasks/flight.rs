//! Take off to a point and fly to a point as running tasks: one tokio task each,
//! which sends the commands, watches the vehicle ([`Monitor`]) and reports.
//!
//! Events (under the starting request's id): a takeoff `Ready` once accepted, then
//! `Progress` every `progress_interval`, and at the end `Arrived` + `Finished`
//! (takeoff) / `Arrived` (fly-to), or `Failed` / `Cancelled`. `way_point_index` is
//! the point being flown to (takeoff: 0 the climb point above the start, 1 the
//! target; fly-to: 0).

use std::time::{Duration, Instant};

use skymesh_ipc_types::{
    Command, FlightMode, FlightTaskStatus, TaskEvent, TaskEventKind, TaskPoint, TaskRequest,
    TaskResult,
};
use skymesh_runtime::clock::monotonic_ns;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use super::link::{Snapshot, TaskLink};
use super::progress::{
    self, is_flying, position, remaining_distance, remaining_time, Monitor, Observation, Verdict,
};
use super::Events;
use crate::shots::{distance_m, GeoPoint};

/// How often the task looks at the vehicle.
const CHECK_EVERY: Duration = Duration::from_millis(100);

/// A task to run. Altitudes are above home.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskSpec {
    /// Takeoff: climb to this height above home first; `None`: a fly-to.
    pub climb_alt_rel_m: Option<f64>,
    pub target: GeoPoint,
    /// `None`: the autopilot's default speed.
    pub speed_mps: Option<f32>,
    pub arrival_radius_m: f64,
    pub stall_timeout: Duration,
    pub progress_interval: Duration,
}

impl TaskSpec {
    /// From a Takeoff or FlyTo request.
    pub fn from_request(r: &TaskRequest, takeoff: bool) -> Self {
        TaskSpec {
            climb_alt_rel_m: if takeoff {
                Some(f64::from(r.climb().unwrap_or(r.target.alt_rel_m)))
            } else {
                None
            },
            target: geo(&r.target),
            speed_mps: r.speed(),
            arrival_radius_m: f64::from(r.arrival_radius_m),
            stall_timeout: Duration::from_secs_f32(r.stall_timeout_s.clamp(0.1, 3600.0)),
            progress_interval: Duration::from_millis(u64::from(r.progress_interval_ms.max(100))),
        }
    }
}

/// A bus point as a [`GeoPoint`].
pub fn geo(p: &TaskPoint) -> GeoPoint {
    GeoPoint {
        lat_deg: p.lat_deg,
        lon_deg: p.lon_deg,
        alt_rel_m: p.alt_rel_m,
    }
}

fn point(p: &GeoPoint) -> TaskPoint {
    TaskPoint {
        lat_deg: p.lat_deg,
        lon_deg: p.lon_deg,
        alt_rel_m: p.alt_rel_m,
        reserved: 0,
    }
}

/// Requests to a running task.
#[derive(Debug)]
pub enum Control {
    /// Brake, `Cancelled`, reply to `request`.
    Stop { request: TaskRequest },
    /// A new target (and speed), reply to `request`.
    Update {
        target: GeoPoint,
        speed_mps: Option<f32>,
        request: TaskRequest,
    },
    /// Another task or an orbit takes over: `Cancelled` (result ok), no brake.
    Preempt,
}

/// The runner's side of a running task.
#[derive(Debug)]
pub struct TaskHandle {
    pub control: mpsc::UnboundedSender<Control>,
    pub join: JoinHandle<()>,
}

impl TaskHandle {
    pub fn is_running(&self) -> bool {
        !self.join.is_finished()
    }
}

/// Starts `spec` for `request`; the task replies (ok once its first flight command
/// was accepted) and ends by itself.
pub fn spawn(link: TaskLink, events: Events, spec: TaskSpec, request: TaskRequest) -> TaskHandle {
    let (tx, rx) = mpsc::unbounded_channel();
    let join = tokio::spawn(async move {
        let mut task = Task::new(link, events, spec, request);
        task.run(rx).await;
    });
    TaskHandle { control: tx, join }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    Climb,
    Transit,
}

struct Task {
    link: TaskLink,
    events: Events,
    spec: TaskSpec,
    request: TaskRequest,
    stage: Stage,
    /// Takeoff: the point above the start (set when the climb starts).
    climb_point: Option<GeoPoint>,
    monitor: Monitor,
    what: &'static str,
}

impl Task {
    fn new(link: TaskLink, events: Events, spec: TaskSpec, request: TaskRequest) -> Self {
        let monitor = Monitor::new(spec.arrival_radius_m, spec.stall_timeout);
        let what = if spec.climb_alt_rel_m.is_some() {
            "takeoff"
        } else {
            "fly_to"
        };
        Task {
            link,
            events,
            spec,
            request,
            stage: Stage::Transit,
            climb_point: None,
            monitor,
            what,
        }
    }

    fn takeoff(&self) -> bool {
        self.spec.climb_alt_rel_m.is_some()
    }

    fn goto(&self, p: &GeoPoint) -> Command {
        Command::GoTo {
            lat_deg: p.lat_deg,
            lon_deg: p.lon_deg,
            alt_rel_m: p.alt_rel_m,
            yaw_deg: None,
            speed_mps: self.spec.speed_mps,
        }
    }

    /// The first commands; the result for the reply.
    async fn start(&mut self) -> TaskResult {
        let snap = self.link.snapshot();
        let Some(climb) = self.spec.climb_alt_rel_m else {
            // A fly-to: only a flying vehicle can fly to a point.
            if !is_flying(&snap) {
                return TaskResult::WrongState;
            }
            // GUIDED even when the last status says GUIDED: it repeats the last
            // heartbeat, which may predate a LOITER no heartbeat has shown yet; ArduPilot
            // accepts a request for its current mode and changes nothing.
            let cmds = [
                Command::SetMode(FlightMode::Guided),
                self.goto(&self.spec.target),
            ];
            self.stage = Stage::Transit;
            return self.link.run(self.what, &cmds).await;
        };
        let Some(here) = position(&snap, monotonic_ns()) else {
            return TaskResult::WrongState;
        };
        let climb_point = GeoPoint {
            alt_rel_m: climb as f32,
            ..here
        };
        self.climb_point = Some(climb_point);
        let radius = self.spec.arrival_radius_m;
        let mut cmds = Vec::new();
        if !is_flying(&snap) {
            cmds.extend([
                Command::SetMode(FlightMode::Guided),
                Command::Arm { force: false },
                Command::Takeoff {
                    alt_rel_m: climb as f32,
                },
            ]);
            self.stage = Stage::Climb;
        } else {
            cmds.push(Command::SetMode(FlightMode::Guided));
            if f64::from(here.alt_rel_m) < climb - radius {
                cmds.push(self.goto(&climb_point));
                self.stage = Stage::Climb;
            } else {
                cmds.push(self.goto(&self.spec.target));
                self.stage = Stage::Transit;
            }
        }
        self.link.run(self.what, &cmds).await
    }

    /// The points still to fly, the first being the current leg's end.
    fn remaining_points(&self) -> Vec<GeoPoint> {
        match (self.stage, self.climb_point) {
            (Stage::Climb, Some(c)) => vec![c, self.spec.target],
            _ => vec![self.spec.target],
        }
    }

    fn way_point_index(&self) -> u8 {
        match (self.takeoff(), self.stage) {
            (true, Stage::Transit) => 1,
            _ => 0,
        }
    }

    /// (distance to the leg's end, remaining distance) from the latest samples.
    fn distances(&self, snap: &Snapshot) -> Option<(f64, f64)> {
        let here = position(snap, monotonic_ns())?;
        let points = self.remaining_points();
        let leg = match self.stage {
            // The climb ends at a height: horizontal drift does not matter.
            Stage::Climb => (f64::from(points[0].alt_rel_m) - f64::from(here.alt_rel_m)).max(0.0),
            Stage::Transit => distance_m(&here, &points[0]),
        };
        let rest = match self.stage {
            Stage::Climb => leg + distance_m(&points[0], &points[1]),
            Stage::Transit => remaining_distance(&here, &points),
        };
        Some((leg, rest))
    }

    fn emit(&self, status: FlightTaskStatus, result: TaskResult) {
        let done = matches!(
            status,
            FlightTaskStatus::Arrived | FlightTaskStatus::Finished
        );
        let mut e = TaskEvent {
            request_id: self.request.request_id,
            vehicle_id: self.request.vehicle_id,
            kind: TaskEventKind::Flight.to_wire(),
            source: self.request.source,
            result: result.to_wire(),
            status: status.to_wire(),
            way_point_index: self.way_point_index(),
            ..Default::default()
        };
        if !done {
            let snap = self.link.snapshot();
            if let Some((_, d)) = self.distances(&snap) {
                e.remaining_distance_m = d as f32;
                e.remaining_time_s = remaining_time(d, progress::speed(&snap)) as f32;
            }
            let points: Vec<TaskPoint> = self.remaining_points().iter().map(point).collect();
            e.set_points(&points);
        }
        self.events.publish(e);
    }

    fn finish_ok(&self) {
        self.emit(FlightTaskStatus::Arrived, TaskResult::Ok);
        if self.takeoff() {
            self.emit(FlightTaskStatus::Finished, TaskResult::Ok);
        }
        tracing::info!(what = self.what, "task reached its target");
    }

    async fn run(&mut self, mut control: mpsc::UnboundedReceiver<Control>) {
        let result = self.start().await;
        self.events.reply(&self.request, result);
        if result != TaskResult::Ok {
            return;
        }
        tracing::info!(what = self.what, target = ?self.spec.target, stage = ?self.stage, "task started");
        if self.takeoff() {
            self.emit(FlightTaskStatus::Ready, TaskResult::Ok);
        }
        let mut watch = tokio::time::interval(CHECK_EVERY);
        watch.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut progress = tokio::time::interval(self.spec.progress_interval);
        progress.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                c = control.recv() => match c {
                    // The runner dropped us (shutdown): leave the vehicle to the arbiter.
                    None => return,
                    Some(Control::Preempt) => {
                        self.emit(FlightTaskStatus::Cancelled, TaskResult::Ok);
                        return;
                    }
                    Some(Control::Stop { request }) => {
                        let r = self.link.run("fly_to_stop", &[Command::Brake]).await;
                        self.events.reply(&request, r);
                        self.emit(FlightTaskStatus::Cancelled, TaskResult::Ok);
                        return;
                    }
                    Some(Control::Update { target, speed_mps, request }) => {
                        let r = self.update(target, speed_mps).await;
                        self.events.reply(&request, r);
                    }
                },
                _ = progress.tick() => self.emit(FlightTaskStatus::Progress, TaskResult::Ok),
                _ = watch.tick() => {
                    if self.check().await {
                        return;
                    }
                }
            }
        }
    }

    async fn update(&mut self, target: GeoPoint, speed_mps: Option<f32>) -> TaskResult {
        let old = (self.spec.target, self.spec.speed_mps);
        self.spec.target = target;
        self.spec.speed_mps = speed_mps;
        if self.stage == Stage::Climb {
            // Flown to once the climb ends.
            return TaskResult::Ok;
        }
        let r = self.link.run("fly_to_update", &[self.goto(&target)]).await;
        if r == TaskResult::Ok {
            self.monitor.restart_progress();
        } else {
            (self.spec.target, self.spec.speed_mps) = old;
        }
        r
    }

    /// One look at the vehicle; `true` when the task ended.
    async fn check(&mut self) -> bool {
        let snap = self.link.snapshot();
        let d = self.distances(&snap);
        let o = Observation::from_snapshot(&snap, d.map(|x| x.0), d.map(|x| x.1));
        match self.monitor.update(&o, Instant::now()) {
            Verdict::Continue => false,
            Verdict::Arrived if self.stage == Stage::Climb => {
                let goto = self.goto(&self.spec.target);
                let r = self.link.run(self.what, &[goto]).await;
                if r != TaskResult::Ok {
                    self.emit(FlightTaskStatus::Failed, r);
                    return true;
                }
                self.stage = Stage::Transit;
                self.monitor.restart_progress();
                tracing::info!(what = self.what, "climb done, flying to the target");
                false
            }
            Verdict::Arrived => {
                self.finish_ok();
                true
            }
            Verdict::Cancelled(r) => {
                tracing::info!(what = self.what, result = %r, "task pre-empted");
                self.emit(FlightTaskStatus::Cancelled, r);
                true
            }
            Verdict::Failed(r) => {
                tracing::warn!(what = self.what, result = %r, "task failed");
                if r == TaskResult::WrongState && o.mode == FlightMode::Guided && o.holds_flight {
                    // Stalled while still ours: stop where it is.
                    let _ = self.link.run(self.what, &[Command::Brake]).await;
                }
                self.emit(FlightTaskStatus::Failed, r);
                true
            }
        }
    }
}
