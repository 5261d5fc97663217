//! POI mode as a running task: GUIDED, `SetRoi` on the point, then a velocity
//! setpoint every [`poi::TICK`] from the [`PoiController`] (max age
//! [`poi::SETPOINT_MAX_AGE_MS`]: if the gateway stops, the arbiter brakes).
//! poi_status_notify (need_reply 1) on enter, on every speed change, on exit and on
//! failure. Exit: `Brake`, `ClearRoi`.

use std::time::Instant;

use dji_proto::{codes, Envelope, PoiStatus};
use skymesh_ipc_types::{Command, FlightMode};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_shot_engine::shots::{GeoPoint, VehicleView};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::poi::{self, reason, PoiController};
use crate::progress::FAILURE_DEBOUNCE;
use crate::shared::{run_commands, Shared};

const METHOD: &str = "poi_status_notify";

/// Requests to a running POI.
#[derive(Debug)]
pub enum PoiControl {
    /// poi_circle_speed_set (already range-checked).
    Speed { speed: f64, request: Envelope },
    /// poi_mode_exit.
    Exit { request: Envelope },
    /// A flight task takes over: status ok, no brake.
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

/// Starts orbiting `point` (altitude above home) from `view`; replies to `request`.
pub fn spawn(shared: Shared, point: GeoPoint, view: VehicleView, request: Envelope) -> PoiHandle {
    let (tx, rx) = mpsc::unbounded_channel();
    let join = tokio::spawn(run(shared, point, view, request, rx));
    PoiHandle { control: tx, join }
}

async fn run(
    shared: Shared,
    point: GeoPoint,
    view: VehicleView,
    request: Envelope,
    mut control: mpsc::UnboundedReceiver<PoiControl>,
) {
    let p = &shared.settings.poi;
    let mut c = PoiController::new(
        point,
        &view,
        p.initial_circle_speed_mps,
        p.max_circle_speed_mps,
    );
    let link = &shared.link;
    // GUIDED is asked for even when the last status says GUIDED: that status repeats
    // the last heartbeat, which may predate a LOITER (a Solo shot that just ended);
    // ArduPilot answers a request for its current mode as accepted and changes nothing.
    let start = [
        Command::SetMode(FlightMode::Guided),
        Command::SetRoi {
            lat_deg: point.lat_deg,
            lon_deg: point.lon_deg,
            alt_rel_m: point.alt_rel_m,
        },
    ];
    let r = run_commands(link, "poi_mode_enter", &start).await;
    shared.emit.reply(request, r);
    if r != codes::OK {
        shared.emit.event(
            METHOD,
            c.status(PoiStatus::Failed, reason::FLIGHT_MODE_ERROR),
            true,
        );
        return;
    }
    tracing::info!(point = ?point, radius_m = c.radius_m(), speed = c.speed(), "POI orbit started");
    shared.emit.event(
        METHOD,
        c.status(PoiStatus::InProgress, reason::NORMAL),
        true,
    );
    let mut tick = tokio::time::interval(poi::TICK);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last = Instant::now();
    // Since when a reason to stop has held (samples may lag the commands above).
    let mut failing: Option<(Instant, u8)> = None;
    loop {
        tokio::select! {
            msg = control.recv() => match msg {
                None => return,
                Some(PoiControl::Preempt) => {
                    shared.emit.event(METHOD, c.status(PoiStatus::Ok, reason::NORMAL), true);
                    return;
                }
                Some(PoiControl::Exit { request }) => {
                    let r = run_commands(link, "poi_mode_exit", &[Command::Brake, Command::ClearRoi]).await;
                    shared.emit.reply(request, r);
                    shared.emit.event(METHOD, c.status(PoiStatus::Ok, reason::NORMAL), true);
                    tracing::info!("POI orbit ended by the cloud");
                    return;
                }
                Some(PoiControl::Speed { speed, request }) => {
                    c.set_speed(speed);
                    shared.emit.reply(request, codes::OK);
                    shared.emit.event(METHOD, c.status(PoiStatus::InProgress, reason::NORMAL), true);
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
                            tracing::warn!(reason = why, "POI orbit ended: the vehicle cannot orbit now");
                            shared.emit.event(METHOD, c.status(PoiStatus::Failed, why), true);
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
