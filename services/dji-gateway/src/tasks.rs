//! takeoff_to_point, fly_to_point (stop, update), POI mode and the panorama
//! capture, translated: the flying (and the gimbal sweep) is done by the shot
//! engine's task runner, reached over the bus
//! ([`TaskRequest`] / [`TaskEvent`], `skymesh/task/{id}/{request,event}`). The
//! runner commands the vehicle as this gateway's source (`dji_drc`), so authority,
//! refusals and acks read as if the gateway had sent the commands.
//!
//! Every request is answered: by the runner's reply, mapped to a DJI result code
//! ([`result_code`]); with `INTERNAL` when no runner reads the request topic within
//! [`BACKEND_WAIT`] (the shot engine is not running), or when a reply does not come
//! within [`TaskClient::reply_timeout`]. The runner's events become
//! `takeoff_to_point_progress` / `fly_to_point_progress` (the DJI ids and the
//! ellipsoid heights are the gateway's: kept per task here), `poi_status_notify`
//! and `camera_photo_take_progress` ([`crate::pano`]).

use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use anyhow::Context as _;
use dji_proto::{
    codes, Envelope, FlyToPointProgress, PoiStatus, PoiStatusNotify, TakeoffToPointProgress,
    TaskStatus,
};
use skymesh_ipc_types::{
    topics, FlightTaskStatus, PoiReason, PoiTaskStatus, TaskEvent, TaskEventKind, TaskPoint,
    TaskRequest, TaskRequestKind, TaskResult,
};
use skymesh_runtime::backend::BackendWait;
use skymesh_runtime::{Bus, CancellationToken, Publisher};

use crate::config::Settings;
use crate::link::SOURCE;
use crate::pano;
use crate::progress::{path_points, round1, Heights};
use crate::shared::Emitter;

/// How long a request waits for a task runner to read the request topic before the
/// gateway answers `INTERNAL` itself (once gone, later requests are answered at once
/// until a runner is back).
pub const BACKEND_WAIT: Duration = Duration::from_secs(2);

/// Which DJI task a flight task is, with the ids its events carry.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FlightKind {
    Takeoff { flight_id: String },
    FlyTo { fly_to_id: String },
}

#[derive(Debug, Clone)]
struct FlightInfo {
    kind: FlightKind,
    heights: Heights,
}

/// What a request starts (kept until its task's terminal event).
enum Starts {
    Nothing,
    Flight(FlightInfo),
    Poi,
    Pano,
}

/// What the reply to a request becomes.
pub enum OnReply {
    /// The DJI code of the runner's result.
    Code,
    /// camera_photo_take of a panorama: ok is 0 with `output.status` `in_progress`.
    PanoStarted,
    /// The runner has no such task (`NO_TASK`): this handles the request instead
    /// (camera_photo_stop of a panorama that ended meanwhile: an ordinary stop).
    OrElse(Box<dyn FnOnce(Envelope) + Send>),
}

impl std::fmt::Debug for OnReply {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            OnReply::Code => "Code",
            OnReply::PanoStarted => "PanoStarted",
            OnReply::OrElse(_) => "OrElse",
        })
    }
}

#[derive(Debug, Default)]
struct State {
    /// Requests waiting for their reply.
    pending: HashMap<u32, (Envelope, OnReply)>,
    /// Flight tasks asked for and not ended, by their request id.
    flights: HashMap<u32, FlightInfo>,
    /// Orbits asked for and not ended.
    pois: HashSet<u32>,
    /// Panoramas asked for and not ended.
    panos: HashSet<u32>,
}

/// Cheap to clone.
#[derive(Debug, Clone)]
pub struct TaskClient {
    settings: Arc<Settings>,
    requests: Arc<Mutex<Publisher<TaskRequest>>>,
    next_id: Arc<AtomicU32>,
    state: Arc<Mutex<State>>,
    wait: Arc<tokio::sync::Mutex<BackendWait>>,
    emit: Emitter,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// A DJI result code for a runner's result.
pub fn result_code(r: TaskResult) -> u32 {
    match r {
        TaskResult::Ok => codes::OK,
        TaskResult::InvalidParameter => codes::OUT_OF_RANGE,
        TaskResult::Internal => codes::INTERNAL,
        TaskResult::VehicleUnavailable => codes::VEHICLE_UNAVAILABLE,
        TaskResult::NoFlightAuthority => codes::FLIGHT_AUTHORITY_REQUIRED,
        TaskResult::NoPayloadAuthority => codes::PAYLOAD_AUTHORITY_REQUIRED,
        TaskResult::WrongState => codes::WRONG_STATE,
        TaskResult::Refused => codes::REFUSED_BY_ARBITER,
        TaskResult::NoTask => codes::NO_TASK,
        TaskResult::PayloadUnsupported => codes::PAYLOAD_UNSUPPORTED,
    }
}

/// poi_status_notify `reason` (the document's table).
pub fn poi_reason(r: PoiReason) -> u8 {
    match r {
        PoiReason::Normal => 0,
        PoiReason::PositioningFailure => 4,
        PoiReason::NotTakenOff => 5,
        PoiReason::FlightModeError => 6,
        PoiReason::UnavailableMode => 7,
        PoiReason::LinkLost => 8,
    }
}

/// The DJI status of a flight task's status, and whether its event needs a reply
/// (terminal events are re-sent until the cloud answers).
pub fn task_status(s: FlightTaskStatus) -> (TaskStatus, bool) {
    match s {
        FlightTaskStatus::Ready => (TaskStatus::TaskReady, false),
        FlightTaskStatus::Progress => (TaskStatus::WaylineProgress, false),
        FlightTaskStatus::Arrived => (TaskStatus::WaylineOk, true),
        FlightTaskStatus::Finished => (TaskStatus::TaskFinish, true),
        FlightTaskStatus::Failed => (TaskStatus::WaylineFailed, true),
        FlightTaskStatus::Cancelled => (TaskStatus::WaylineCancel, true),
    }
}

/// An f32 from the bus as the decimal it was sent as (6 decimals).
fn decimal(x: f32) -> f64 {
    (f64::from(x) * 1e6).round() / 1e6
}

/// poi_status_notify data of a Poi event.
pub fn poi_notify(e: &TaskEvent) -> Option<PoiStatusNotify> {
    let status = match e.poi_status().ok()? {
        PoiTaskStatus::InProgress => PoiStatus::InProgress,
        PoiTaskStatus::Ended => PoiStatus::Ok,
        PoiTaskStatus::Failed => PoiStatus::Failed,
    };
    Some(PoiStatusNotify {
        status,
        reason: poi_reason(e.poi_reason().ok()?),
        circle_radius: round1(f64::from(e.circle_radius_m)),
        circle_speed: decimal(e.circle_speed_mps),
        max_circle_speed: decimal(e.max_circle_speed_mps),
    })
}

/// A point above home for the runner.
pub fn task_point(lat_deg: f64, lon_deg: f64, alt_rel_m: f64) -> TaskPoint {
    TaskPoint {
        lat_deg,
        lon_deg,
        alt_rel_m: alt_rel_m as f32,
        reserved: 0,
    }
}

impl TaskClient {
    /// Opens the request and event topics and starts the task that translates the
    /// runner's events (it ends with `shutdown`).
    pub fn open(
        bus: &Bus,
        settings: Arc<Settings>,
        emit: Emitter,
        shutdown: CancellationToken,
    ) -> anyhow::Result<Self> {
        let id = settings.vehicle_id;
        let requests = bus
            .publisher::<TaskRequest>(&topics::task_request(id))
            .context("opening the task request topic")?;
        let mut events = bus
            .subscriber::<TaskEvent>(&topics::task_event(id))
            .context("opening the task event topic")?;
        let client = TaskClient {
            settings,
            requests: Arc::new(Mutex::new(requests)),
            next_id: Arc::new(AtomicU32::new(1)),
            state: Arc::default(),
            wait: Arc::default(),
            emit,
        };
        let c = client.clone();
        tokio::spawn(async move {
            loop {
                tokio::select! {
                    _ = shutdown.cancelled() => break,
                    r = events.recv() => match r {
                        Ok(e) => c.on_event(&e),
                        Err(e) => {
                            tracing::error!(error = %e, "task event subscription failed");
                            break;
                        }
                    },
                }
            }
        });
        Ok(client)
    }

    /// True while a takeoff / fly-to asked for has not ended.
    pub fn task_active(&self) -> bool {
        !lock(&self.state).flights.is_empty()
    }

    /// True while an orbit asked for has not ended.
    pub fn poi_active(&self) -> bool {
        !lock(&self.state).pois.is_empty()
    }

    /// True while a panorama asked for has not ended.
    pub fn pano_active(&self) -> bool {
        !lock(&self.state).panos.is_empty()
    }

    /// How long a request waits for the runner's reply: the runner sends up to
    /// three commands before it answers, each waiting up to the ack timeout.
    pub fn reply_timeout(&self) -> Duration {
        self.settings.commands.ack_timeout * 4 + Duration::from_secs(1)
    }

    fn base(&self, kind: TaskRequestKind) -> TaskRequest {
        let f = &self.settings.flight;
        TaskRequest {
            vehicle_id: self.settings.vehicle_id,
            kind: kind.to_wire(),
            source: SOURCE.to_wire(),
            climb_alt_rel_m: f32::NAN,
            speed_mps: f32::NAN,
            max_speed_mps: self.settings.poi.max_circle_speed_mps as f32,
            arrival_radius_m: f.arrival_radius_m as f32,
            stall_timeout_s: f.stall_timeout.as_secs_f32(),
            progress_interval_ms: u32::try_from(f.progress_interval.as_millis())
                .unwrap_or(u32::MAX),
            ack_timeout_ms: u32::try_from(self.settings.commands.ack_timeout.as_millis())
                .unwrap_or(u32::MAX),
            ..Default::default()
        }
    }

    /// takeoff_to_point: climb to `climb_alt_rel_m`, then fly to `target`.
    pub fn takeoff(
        &self,
        env: Envelope,
        flight_id: String,
        climb_alt_rel_m: f64,
        target: TaskPoint,
        speed_mps: f32,
        heights: Heights,
    ) {
        let req = TaskRequest {
            target,
            climb_alt_rel_m: climb_alt_rel_m as f32,
            speed_mps,
            ..self.base(TaskRequestKind::Takeoff)
        };
        let info = FlightInfo {
            kind: FlightKind::Takeoff { flight_id },
            heights,
        };
        self.request(env, req, Starts::Flight(info));
    }

    /// fly_to_point (`speed_mps` `None`: the autopilot's own speed).
    pub fn fly_to(
        &self,
        env: Envelope,
        fly_to_id: String,
        target: TaskPoint,
        speed_mps: Option<f32>,
        heights: Heights,
    ) {
        let req = TaskRequest {
            target,
            speed_mps: speed_mps.unwrap_or(f32::NAN),
            ..self.base(TaskRequestKind::FlyTo)
        };
        let info = FlightInfo {
            kind: FlightKind::FlyTo { fly_to_id },
            heights,
        };
        self.request(env, req, Starts::Flight(info));
    }

    /// fly_to_point_stop.
    pub fn stop(&self, env: Envelope) {
        self.request(env, self.base(TaskRequestKind::FlyToStop), Starts::Nothing);
    }

    /// fly_to_point_update.
    pub fn update(&self, env: Envelope, target: TaskPoint, speed_mps: f32) {
        let req = TaskRequest {
            target,
            speed_mps,
            ..self.base(TaskRequestKind::FlyToUpdate)
        };
        self.request(env, req, Starts::Nothing);
    }

    /// poi_mode_enter around `point` (altitude above home).
    pub fn poi_enter(&self, env: Envelope, point: TaskPoint) {
        let req = TaskRequest {
            target: point,
            speed_mps: self.settings.poi.initial_circle_speed_mps as f32,
            ..self.base(TaskRequestKind::PoiEnter)
        };
        self.request(env, req, Starts::Poi);
    }

    /// poi_circle_speed_set (already range-checked).
    pub fn poi_speed(&self, env: Envelope, speed: f64) {
        let req = TaskRequest {
            speed_mps: speed as f32,
            ..self.base(TaskRequestKind::PoiSpeed)
        };
        self.request(env, req, Starts::Nothing);
    }

    /// poi_mode_exit.
    pub fn poi_exit(&self, env: Envelope) {
        self.request(env, self.base(TaskRequestKind::PoiExit), Starts::Nothing);
    }

    /// camera_photo_take in panorama mode (`clear_roi`: camera_look_at's ROI would
    /// hold the gimbal).
    pub fn pano_start(&self, env: Envelope, clear_roi: bool) {
        let p = &self.settings.payload;
        let req = TaskRequest {
            pano_stations: u8::try_from(p.pano_stations).unwrap_or(u8::MAX),
            pano_pitch_deg: p.pano_pitch_deg as f32,
            pano_settle_timeout_ms: u32::try_from(p.pano_settle_timeout.as_millis())
                .unwrap_or(u32::MAX),
            pano_clear_roi: u8::from(clear_roi),
            ..self.base(TaskRequestKind::PanoStart)
        };
        self.send(env, req, Starts::Pano, OnReply::PanoStarted);
    }

    /// camera_photo_stop of a running panorama; `otherwise` handles it if the
    /// panorama ended meanwhile.
    pub fn pano_stop(&self, env: Envelope, otherwise: Box<dyn FnOnce(Envelope) + Send>) {
        let req = self.base(TaskRequestKind::PanoStop);
        self.send(env, req, Starts::Nothing, OnReply::OrElse(otherwise));
    }

    fn runner_reads(&self) -> bool {
        lock(&self.requests).subscribers() > 0
    }

    fn request(&self, env: Envelope, req: TaskRequest, starts: Starts) {
        self.send(env, req, starts, OnReply::Code);
    }

    fn send(&self, env: Envelope, mut req: TaskRequest, starts: Starts, on: OnReply) {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        req.request_id = id;
        {
            let mut s = lock(&self.state);
            s.pending.insert(id, (env, on));
            match starts {
                Starts::Nothing => {}
                Starts::Flight(info) => {
                    s.flights.insert(id, info);
                }
                Starts::Poi => {
                    s.pois.insert(id);
                }
                Starts::Pano => {
                    s.panos.insert(id);
                }
            }
        }
        if self.runner_reads() {
            self.publish(req);
        } else {
            let c = self.clone();
            tokio::spawn(async move {
                let present = c
                    .wait
                    .lock()
                    .await
                    .present(BACKEND_WAIT, || c.runner_reads())
                    .await;
                if present {
                    c.publish(req);
                } else {
                    tracing::warn!(
                        kind = req.kind,
                        "no task runner (is the shot engine running?): answered internal error"
                    );
                    c.answer(id, codes::INTERNAL);
                    // Without a runner no task runs: none is waited for any more.
                    let mut s = lock(&c.state);
                    s.flights.clear();
                    s.pois.clear();
                    s.panos.clear();
                }
            });
        }
    }

    fn publish(&self, req: TaskRequest) {
        let id = req.request_id;
        if let Err(e) = lock(&self.requests).publish(req) {
            tracing::error!(error = %e, "task request not published");
            return self.answer(id, codes::INTERNAL);
        }
        let c = self.clone();
        tokio::spawn(async move {
            tokio::time::sleep(c.reply_timeout()).await;
            if lock(&c.state).pending.contains_key(&id) {
                tracing::warn!(id, "the task runner did not answer: internal error");
                c.answer(id, codes::INTERNAL);
            }
        });
    }

    /// Replies `code` to request `id` if it still waits; a refused request starts
    /// nothing.
    fn answer(&self, id: u32, code: u32) {
        let waiting = {
            let mut s = lock(&self.state);
            if code != codes::OK {
                s.flights.remove(&id);
                s.pois.remove(&id);
                s.panos.remove(&id);
            }
            s.pending.remove(&id)
        };
        match waiting {
            None => {}
            Some((env, OnReply::PanoStarted)) if code == codes::OK => self.emit.reply_with_output(
                env,
                code,
                serde_json::json!({ "status": "in_progress" }),
            ),
            Some((env, OnReply::OrElse(otherwise))) if code == codes::NO_TASK => otherwise(env),
            Some((env, _)) => self.emit.reply(env, code),
        }
    }

    fn on_event(&self, e: &TaskEvent) {
        if e.source != SOURCE.to_wire() || e.vehicle_id != self.settings.vehicle_id {
            return;
        }
        match e.kind() {
            Ok(TaskEventKind::Reply) => match e.result() {
                Ok(r) => self.answer(e.request_id, result_code(r)),
                Err(err) => {
                    tracing::warn!(error = %err, "task reply with an unknown result");
                    self.answer(e.request_id, codes::INTERNAL);
                }
            },
            Ok(TaskEventKind::Flight) => self.on_flight(e),
            Ok(TaskEventKind::Poi) => {
                let Some(n) = poi_notify(e) else {
                    return tracing::warn!(?e, "POI event with unknown values");
                };
                if n.status != PoiStatus::InProgress {
                    lock(&self.state).pois.remove(&e.request_id);
                }
                self.emit.event("poi_status_notify", n, true);
            }
            Ok(TaskEventKind::Pano) => self.on_pano(e),
            Err(err) => tracing::warn!(error = %err, "unknown task event"),
        }
    }

    fn on_pano(&self, e: &TaskEvent) {
        let Some((data, ends)) = pano::progress(e) else {
            return tracing::warn!(?e, "panorama event with an unknown status");
        };
        {
            let mut s = lock(&self.state);
            let known = if ends {
                s.panos.remove(&e.request_id)
            } else {
                s.panos.contains(&e.request_id)
            };
            if !known {
                return tracing::debug!(
                    id = e.request_id,
                    "event of a panorama not asked for here"
                );
            }
        }
        self.emit.event(pano::METHOD, data, ends);
    }

    fn on_flight(&self, e: &TaskEvent) {
        let Ok(status) = e.flight_status() else {
            return tracing::warn!(?e, "flight task event with an unknown status");
        };
        let (status, need_reply) = task_status(status);
        let info = {
            let mut s = lock(&self.state);
            if need_reply && status != TaskStatus::WaylineOk {
                s.flights.remove(&e.request_id)
            } else {
                s.flights.get(&e.request_id).cloned()
            }
        };
        let Some(info) = info else {
            return tracing::debug!(id = e.request_id, "event of a task not asked for here");
        };
        if status == TaskStatus::WaylineOk && matches!(info.kind, FlightKind::FlyTo { .. }) {
            // A fly-to ends at its wayline_ok (a takeoff at task_finish).
            lock(&self.state).flights.remove(&e.request_id);
        }
        let result = e.result().map_or(codes::INTERNAL, result_code);
        let points = path_points(e.points(), &info.heights);
        let remaining = round1(f64::from(e.remaining_distance_m));
        let time = round1(f64::from(e.remaining_time_s));
        let index = i64::from(e.way_point_index);
        match info.kind {
            FlightKind::Takeoff { flight_id } => self.emit.event(
                "takeoff_to_point_progress",
                TakeoffToPointProgress {
                    status,
                    result,
                    // skymesh records no separate track: the flight id names it.
                    track_id: flight_id.clone(),
                    flight_id,
                    way_point_index: index,
                    remaining_distance: remaining,
                    remaining_time: time,
                    planned_path_points: points,
                },
                need_reply,
            ),
            FlightKind::FlyTo { fly_to_id } => self.emit.event(
                "fly_to_point_progress",
                FlyToPointProgress {
                    fly_to_id,
                    status,
                    result,
                    way_point_index: index,
                    remaining_distance: remaining,
                    remaining_time: time,
                    planned_path_points: points,
                },
                need_reply,
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_result_has_its_dji_code() {
        assert_eq!(result_code(TaskResult::Ok), codes::OK);
        assert_eq!(
            result_code(TaskResult::NoFlightAuthority),
            codes::FLIGHT_AUTHORITY_REQUIRED
        );
        assert_eq!(result_code(TaskResult::NoTask), codes::NO_TASK);
        assert_eq!(result_code(TaskResult::Refused), codes::REFUSED_BY_ARBITER);
        for r in TaskResult::ALL {
            assert!(r == &TaskResult::Ok || result_code(*r) != codes::OK, "{r}");
        }
    }

    #[test]
    fn statuses_and_reasons_follow_the_document() {
        assert_eq!(
            task_status(FlightTaskStatus::Progress),
            (TaskStatus::WaylineProgress, false)
        );
        assert_eq!(
            task_status(FlightTaskStatus::Cancelled),
            (TaskStatus::WaylineCancel, true)
        );
        assert_eq!(poi_reason(PoiReason::NotTakenOff), 5);
        assert_eq!(poi_reason(PoiReason::LinkLost), 8);
    }

    #[test]
    fn poi_events_report_radius_and_speeds() {
        let e = TaskEvent {
            kind: TaskEventKind::Poi.to_wire(),
            status: PoiTaskStatus::InProgress.to_wire(),
            reason: PoiReason::Normal.to_wire(),
            circle_radius_m: 12.34,
            circle_speed_mps: -0.3,
            max_circle_speed_mps: 5.0,
            ..Default::default()
        };
        let n = poi_notify(&e).unwrap();
        assert_eq!(n.status, PoiStatus::InProgress);
        assert_eq!(n.circle_radius, 12.3);
        assert_eq!((n.circle_speed, n.max_circle_speed), (-0.3, 5.0));
    }
}
