//! takeoff_to_point and fly_to_point as running tasks: one tokio task each, which
//! sends the commands, watches the vehicle ([`Monitor`]) and emits the progress
//! events. The services loop holds its [`TaskHandle`] for stop, update and
//! pre-emption.
//!
//! Events: takeoff `task_ready` once accepted, then `wayline_progress` every
//! `progress_interval` (need_reply 0: a lost one is superseded by the next), and at
//! the end `wayline_ok` + `task_finish` (takeoff) / `wayline_ok` (flyto), or
//! `wayline_failed` / `wayline_cancel` — terminal events with need_reply 1, re-sent
//! until the cloud answers. `way_point_index` is the point being flown to (takeoff:
//! 0 the climb point above the start, 1 the target; flyto: 0).

use std::time::Instant;

use dji_proto::{codes, Envelope, FlyToPointProgress, TakeoffToPointProgress, TaskStatus};
use skymesh_ipc_types::{Command, FlightMode};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_shot_engine::shots::{distance_m, GeoPoint};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::progress::{
    self, is_flying, path_points, position, remaining_distance, remaining_time, round1, Heights,
    Monitor, Observation, Verdict,
};
use crate::shared::{run_commands, Shared};

/// How often the task looks at the vehicle.
const CHECK_EVERY: std::time::Duration = std::time::Duration::from_millis(100);

/// Which DJI task this is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TaskKind {
    Takeoff { flight_id: String },
    FlyTo { fly_to_id: String },
}

/// A task to run. Altitudes are above home.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskSpec {
    pub kind: TaskKind,
    /// Takeoff: climb to this height above home first.
    pub climb_alt_rel_m: Option<f64>,
    pub target: GeoPoint,
    /// `None`: the autopilot's default speed.
    pub speed_mps: Option<f32>,
    pub heights: Heights,
}

/// Requests to a running task.
#[derive(Debug)]
pub enum Control {
    /// fly_to_point_stop: brake, `wayline_cancel`, reply to `request`.
    Stop { request: Envelope },
    /// fly_to_point_update: a new target (and speed), reply to `request`.
    Update {
        target: GeoPoint,
        speed_mps: Option<f32>,
        request: Envelope,
    },
    /// Another cloud task or POI takes over: `wayline_cancel` (result 0), no brake.
    Preempt,
}

/// The services loop's side of a running task.
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

/// Starts `spec`; the task replies to `request` (0 once its first flight command
/// was accepted) and ends by itself.
pub fn spawn(shared: Shared, spec: TaskSpec, request: Envelope) -> TaskHandle {
    let (tx, rx) = mpsc::unbounded_channel();
    let join = tokio::spawn(async move {
        let mut task = Task::new(shared, spec);
        task.run(request, rx).await;
    });
    TaskHandle { control: tx, join }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    Climb,
    Transit,
}

struct Task {
    shared: Shared,
    spec: TaskSpec,
    stage: Stage,
    /// Takeoff: the point above the start (set when the climb starts).
    climb_point: Option<GeoPoint>,
    monitor: Monitor,
    method: &'static str,
}

impl Task {
    fn new(shared: Shared, spec: TaskSpec) -> Self {
        let f = &shared.settings.flight;
        let monitor = Monitor::new(f.arrival_radius_m, f.stall_timeout);
        let method = match spec.kind {
            TaskKind::Takeoff { .. } => "takeoff_to_point_progress",
            TaskKind::FlyTo { .. } => "fly_to_point_progress",
        };
        Task {
            shared,
            spec,
            stage: Stage::Transit,
            climb_point: None,
            monitor,
            method,
        }
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

    /// The first commands; the result for the services reply.
    async fn start(&mut self) -> u32 {
        let link = &self.shared.link;
        let snap = link.snapshot();
        let Some(climb) = self.spec.climb_alt_rel_m else {
            // fly_to_point: only a flying vehicle can fly to a point.
            if !is_flying(&snap) {
                return codes::WRONG_STATE;
            }
            // GUIDED even when the last status says GUIDED: it repeats the last
            // heartbeat, which may predate a LOITER no heartbeat has shown yet; ArduPilot
            // accepts a request for its current mode and changes nothing.
            let cmds = [
                Command::SetMode(FlightMode::Guided),
                self.goto(&self.spec.target),
            ];
            self.stage = Stage::Transit;
            return run_commands(link, self.method, &cmds).await;
        };
        let Some(here) = position(&snap, monotonic_ns()) else {
            return codes::WRONG_STATE;
        };
        let climb_point = GeoPoint {
            alt_rel_m: climb as f32,
            ..here
        };
        self.climb_point = Some(climb_point);
        let radius = self.shared.settings.flight.arrival_radius_m;
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
        run_commands(link, self.method, &cmds).await
    }

    /// The points still to fly, the first being the current leg's end.
    fn remaining_points(&self) -> Vec<GeoPoint> {
        match (self.stage, self.climb_point) {
            (Stage::Climb, Some(c)) => vec![c, self.spec.target],
            _ => vec![self.spec.target],
        }
    }

    fn way_point_index(&self) -> i64 {
        match (&self.spec.kind, self.stage) {
            (TaskKind::Takeoff { .. }, Stage::Transit) => 1,
            _ => 0,
        }
    }

    /// (distance to the leg's end, remaining distance) from the latest samples.
    fn distances(&self, snap: &crate::link::Snapshot) -> Option<(f64, f64)> {
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

    fn emit(&self, status: TaskStatus, result: u32, need_reply: bool) {
        let snap = self.shared.link.snapshot();
        let (remaining, time) = match status {
            TaskStatus::WaylineOk | TaskStatus::TaskFinish => (0.0, 0.0),
            _ => match self.distances(&snap) {
                Some((_, d)) => (round1(d), round1(remaining_time(d, progress::speed(&snap)))),
                None => (0.0, 0.0),
            },
        };
        let points = match status {
            TaskStatus::WaylineOk | TaskStatus::TaskFinish => Vec::new(),
            _ => path_points(&self.remaining_points(), &self.spec.heights),
        };
        let emit = &self.shared.emit;
        match &self.spec.kind {
            TaskKind::Takeoff { flight_id } => emit.event(
                self.method,
                TakeoffToPointProgress {
                    status,
                    result,
                    flight_id: flight_id.clone(),
                    // skymesh records no separate track: the flight id names it.
                    track_id: flight_id.clone(),
                    way_point_index: self.way_point_index(),
                    remaining_distance: remaining,
                    remaining_time: time,
                    planned_path_points: points,
                },
                need_reply,
            ),
            TaskKind::FlyTo { fly_to_id } => emit.event(
                self.method,
                FlyToPointProgress {
                    fly_to_id: fly_to_id.clone(),
                    status,
                    result,
                    way_point_index: self.way_point_index(),
                    remaining_distance: remaining,
                    remaining_time: time,
                    planned_path_points: points,
                },
                need_reply,
            ),
        }
    }

    fn finish_ok(&self) {
        self.emit(TaskStatus::WaylineOk, codes::OK, true);
        if matches!(self.spec.kind, TaskKind::Takeoff { .. }) {
            self.emit(TaskStatus::TaskFinish, codes::OK, true);
        }
        tracing::info!(method = self.method, "task reached its target");
    }

    async fn run(&mut self, request: Envelope, mut control: mpsc::UnboundedReceiver<Control>) {
        let result = self.start().await;
        self.shared.emit.reply(request, result);
        if result != codes::OK {
            return;
        }
        tracing::info!(method = self.method, target = ?self.spec.target, stage = ?self.stage, "task started");
        if matches!(self.spec.kind, TaskKind::Takeoff { .. }) {
            self.emit(TaskStatus::TaskReady, codes::OK, false);
        }
        let mut watch = tokio::time::interval(CHECK_EVERY);
        watch.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut progress = tokio::time::interval(self.shared.settings.flight.progress_interval);
        progress.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                c = control.recv() => match c {
                    // The loop dropped us (shutdown): leave the vehicle to the arbiter.
                    None => return,
                    Some(Control::Preempt) => {
                        self.emit(TaskStatus::WaylineCancel, codes::OK, true);
                        return;
                    }
                    Some(Control::Stop { request }) => {
                        let r = run_commands(&self.shared.link, "fly_to_point_stop", &[Command::Brake]).await;
                        self.shared.emit.reply(request, r);
                        self.emit(TaskStatus::WaylineCancel, codes::OK, true);
                        return;
                    }
                    Some(Control::Update { target, speed_mps, request }) => {
                        let r = self.update(target, speed_mps).await;
                        self.shared.emit.reply(request, r);
                    }
                },
                _ = progress.tick() => self.emit(TaskStatus::WaylineProgress, codes::OK, false),
                _ = watch.tick() => {
                    if self.check().await {
                        return;
                    }
                }
            }
        }
    }

    async fn update(&mut self, target: GeoPoint, speed_mps: Option<f32>) -> u32 {
        let old = (self.spec.target, self.spec.speed_mps);
        self.spec.target = target;
        self.spec.speed_mps = speed_mps;
        if self.stage == Stage::Climb {
            // Flown to once the climb ends.
            return codes::OK;
        }
        let r = run_commands(
            &self.shared.link,
            "fly_to_point_update",
            &[self.goto(&target)],
        )
        .await;
        if r == codes::OK {
            self.monitor.restart_progress();
        } else {
            (self.spec.target, self.spec.speed_mps) = old;
        }
        r
    }

    /// One look at the vehicle; `true` when the task ended.
    async fn check(&mut self) -> bool {
        let snap = self.shared.link.snapshot();
        let d = self.distances(&snap);
        let o = Observation::from_snapshot(&snap, d.map(|x| x.0), d.map(|x| x.1));
        match self.monitor.update(&o, Instant::now()) {
            Verdict::Continue => false,
            Verdict::Arrived if self.stage == Stage::Climb => {
                let goto = self.goto(&self.spec.target);
                let r = run_commands(&self.shared.link, self.method, &[goto]).await;
                if r != codes::OK {
                    self.emit(TaskStatus::WaylineFailed, r, true);
                    return true;
                }
                self.stage = Stage::Transit;
                self.monitor.restart_progress();
                tracing::info!(method = self.method, "climb done, flying to the target");
                false
            }
            Verdict::Arrived => {
                self.finish_ok();
                true
            }
            Verdict::Cancelled(code) => {
                tracing::info!(method = self.method, result = code, "task pre-empted");
                self.emit(TaskStatus::WaylineCancel, code, true);
                true
            }
            Verdict::Failed(code) => {
                tracing::warn!(method = self.method, result = code, "task failed");
                if code == codes::WRONG_STATE && o.mode == FlightMode::Guided && o.holds_flight {
                    // Stalled while still ours: stop where it is.
                    let _ = run_commands(&self.shared.link, self.method, &[Command::Brake]).await;
                }
                self.emit(TaskStatus::WaylineFailed, code, true);
                true
            }
        }
    }
}
