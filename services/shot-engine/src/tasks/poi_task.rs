//! An orbit as a running task: GUIDED, `SetRoi` on the point, then a velocity
//! setpoint every [`poi::TICK`] from the [`PoiController`] (max age
//! [`poi::SETPOINT_MAX_AGE_MS`]: if the runner stops, the arbiter brakes). A Poi
//! event on start, on every speed change, on exit and on failure. Exit: `Brake`,
//! `ClearRoi`.

use std::time::Instant;

use skymesh_ipc_types::{
    Command, FlightMode, PoiReason, PoiTaskStatus, TaskEvent, TaskEventKind, TaskRequest,
    TaskResult,
};
use skymesh_runtime::clock::monotonic_ns;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use super::link::TaskLink;
use super::poi::{self, PoiController};
use super::progress::FAILURE_DEBOUNCE;
use super::Events;
use crate::shots::{GeoPoint, VehicleView};

/// Requests to a running orbit.
#[derive(Debug)]
pub enum PoiControl {
    /// A new speed (already range-checked by the requester).
    Speed { speed: f64, request: TaskRequest },
    /// End it: brake, clear the ROI.
    Exit { request: TaskRequest },
    /// A flight task takes over: status ended, no brake.
    Preempt,
}

#[derive(Debug)]
pub struct PoiHandle {
    pub control: mpsc::UnboundedSender<PoiControl>,
    pub join: JoinHandle<()>,
}

impl PoiHandle {
    pub fn is_running(&self) -> bool {
        !self.join.is_finished()
    }
}

/// The Poi event of orbit `c` (`None`: nothing orbits yet) for `request`.
pub fn status_event(
    request: &TaskRequest,
    c: Option<&PoiController>,
    status: PoiTaskStatus,
    reason: PoiReason,
) -> TaskEvent {
    TaskEvent {
        request_id: request.request_id,
        vehicle_id: request.vehicle_id,
        kind: TaskEventKind::Poi.to_wire(),
        source: request.source,
        status: status.to_wire(),
        reason: reason.to_wire(),
        circle_radius_m: c.map_or(0.0, |c| c.radius_m() as f32),
        circle_speed_mps: c.map_or(0.0, |c| c.speed() as f32),
        max_circle_speed_mps: request.max_speed_mps,
        ..Default::default()
    }
}

/// Starts orbiting `point` (altitude above home) from `view` for `request`.
pub fn spawn(
    link: TaskLink,
    events: super::Events,
    point: GeoPoint,
    view: VehicleView,
    request: TaskRequest,
) -> PoiHandle {
    let (tx, rx) = mpsc::unbounded_channel();
    let join = tokio::spawn(run(link, events, point, view, request, rx));
    PoiHandle { control: tx, join }
}

async fn run(
    link: TaskLink,
    events: Events,
    point: GeoPoint,
    view: VehicleView,
    request: TaskRequest,
    mut control: mpsc::UnboundedReceiver<PoiControl>,
) {
    let mut c = PoiController::new(
        point,
        &view,
        f64::from(request.speed_mps),
        f64::from(request.max_speed_mps),
    );
    let status = |c: &PoiController, s, r| status_event(&request, Some(c), s, r);
    // GUIDED is asked for even when the last status says GUIDED: that status repeats
    // the last heartbeat, which may predate a LOITER (a shot that just ended);
    // ArduPilot answers a request for its current mode as accepted and changes nothing.
    let start = [
        Command::SetMode(FlightMode::Guided),
        Command::SetRoi {
            lat_deg: point.lat_deg,
            lon_deg: point.lon_deg,
            alt_rel_m: point.alt_rel_m,
        },
    ];
    let r = link.run("poi_enter", &start).await;
    events.reply(&request, r);
    if r != TaskResult::Ok {
        events.publish(status(
            &c,
            PoiTaskStatus::Failed,
            PoiReason::FlightModeError,
        ));
        return;
    }
    tracing::info!(point = ?point, radius_m = c.radius_m(), speed = c.speed(), "POI orbit started");
    events.publish(status(&c, PoiTaskStatus::InProgress, PoiReason::Normal));
    let mut tick = tokio::time::interval(poi::TICK);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last = Instant::now();
    // Since when a reason to stop has held (samples may lag the commands above).
    let mut failing: Option<(Instant, PoiReason)> = None;
    loop {
        tokio::select! {
            msg = control.recv() => match msg {
                None => return,
                Some(PoiControl::Preempt) => {
                    events.publish(status(&c, PoiTaskStatus::Ended, PoiReason::Normal));
                    return;
                }
                Some(PoiControl::Exit { request: exit }) => {
                    let r = link.run("poi_exit", &[Command::Brake, Command::ClearRoi]).await;
                    events.reply(&exit, r);
                    events.publish(status(&c, PoiTaskStatus::Ended, PoiReason::Normal));
                    tracing::info!("POI orbit ended on request");
                    return;
                }
                Some(PoiControl::Speed { speed, request: set }) => {
                    c.set_speed(speed);
                    events.reply(&set, TaskResult::Ok);
                    events.publish(status(&c, PoiTaskStatus::InProgress, PoiReason::Normal));
                }
            },
            _ = tick.tick() => {
                let now = Instant::now();
                let dt = now.saturating_duration_since(last).as_secs_f32().clamp(0.001, 0.2);
                last = now;
                let snap = link.snapshot();
                let now_ns = monotonic_ns();
                match poi::running_check(&snap, now_ns) {
                    Some(why) => {
                        let since = match failing {
                            Some((t, _)) => t,
                            None => now,
                        };
                        failing = Some((since, why));
                        if now.saturating_duration_since(since) >= FAILURE_DEBOUNCE {
                            tracing::warn!(reason = %why, "POI orbit ended: the vehicle cannot orbit now");
                            events.publish(status(&c, PoiTaskStatus::Failed, why));
                            return;
                        }
                    }
                    None => failing = None,
                }
                let Some(view) = poi::view(&snap, now_ns) else { continue };
                let vel = c.step(&view, dt);
                let cmd = Command::VelocityNed { vel_ned_mps: vel, yaw_rate_dps: None };
                if let Err(e) = link.send(&cmd, poi::SETPOINT_MAX_AGE_MS) {
                    tracing::warn!(error = %e, "POI setpoint not sent");
                }
            }
        }
    }
}
