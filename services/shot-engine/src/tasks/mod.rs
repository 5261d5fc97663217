//! The task runner: flight and payload tasks a gateway asks for over the bus
//! ([`skymesh_ipc_types::TaskRequest`]), flown here and reported back as
//! [`skymesh_ipc_types::TaskEvent`]s. The DJI gateway's takeoff_to_point,
//! fly_to_point, POI mode and panorama capture are these tasks: the POI is the
//! engine's own [`crate::shots::Orbit`].
//!
//! | module | role |
//! |---|---|
//! | [`link`] | vehicle samples; commands as the requester's source, with their acks |
//! | [`progress`], [`flight`] | take off / fly to a point: pure progress rules, and the running task |
//! | [`poi`], [`poi_task`] | orbit a point: pure rules, and the 25 Hz task |
//! | [`pano`], [`pano_task`] | panorama sweep of the gimbal: pure station plan and progress, and the running sweep |
//!
//! One task at a time flies: a new takeoff, fly-to or orbit pre-empts the running
//! one (it reports `Cancelled` / `Ended`). A panorama only turns the gimbal: it
//! runs beside them, one at a time (a second PanoStart while one runs is
//! `WrongState`). Every request gets one reply.
//!
//! | topic | direction | type |
//! |---|---|---|
//! | `skymesh/task/{id}/request` | subscribe | `TaskRequest` |
//! | `skymesh/task/{id}/event` | publish | `TaskEvent` |

pub mod flight;
pub mod link;
pub mod pano;
pub mod pano_task;
pub mod poi;
pub mod poi_task;
pub mod progress;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context as _;
use skymesh_ipc_types::{
    topics, PoiTaskStatus, TaskEvent, TaskRequest, TaskRequestKind, TaskResult,
};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Bus, CancellationToken, Publisher, Subscriber};

use flight::{Control, TaskHandle, TaskSpec};
use link::{TaskLink, VehicleLink};
use pano_task::{PanoControl, PanoHandle, PanoSpec};
use poi_task::{PoiControl, PoiHandle};

/// Publishes the runner's events. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Events(Arc<Mutex<Publisher<TaskEvent>>>);

impl Events {
    pub fn publish(&self, e: TaskEvent) {
        let mut p = self.0.lock().unwrap_or_else(|p| p.into_inner());
        if let Err(err) = p.publish(e) {
            tracing::error!(error = %err, "task runner: event not published");
        }
    }

    /// The reply to `request`.
    pub fn reply(&self, request: &TaskRequest, result: TaskResult) {
        self.publish(TaskEvent::reply(request, result));
    }
}

/// Opens the runner's ports for `vehicle_id` and runs it until `shutdown`.
pub fn spawn(bus: &Bus, vehicle_id: u8, shutdown: CancellationToken) -> anyhow::Result<()> {
    let link = VehicleLink::open(bus, vehicle_id, shutdown.clone())?;
    let requests = bus
        .subscriber::<TaskRequest>(&topics::task_request(vehicle_id))
        .context("opening the task request topic")?;
    let events = bus
        .publisher::<TaskEvent>(&topics::task_event(vehicle_id))
        .context("opening the task event topic")?;
    let runner = Runner {
        vehicle_id,
        link,
        events: Events(Arc::new(Mutex::new(events))),
        task: None,
        poi: None,
        pano: None,
    };
    tokio::spawn(runner.run(requests, shutdown));
    Ok(())
}

struct Runner {
    vehicle_id: u8,
    link: VehicleLink,
    events: Events,
    task: Option<TaskHandle>,
    poi: Option<PoiHandle>,
    pano: Option<PanoHandle>,
}

impl Runner {
    async fn run(mut self, mut requests: Subscriber<TaskRequest>, shutdown: CancellationToken) {
        loop {
            tokio::select! {
                _ = shutdown.cancelled() => break,
                r = requests.recv() => match r {
                    Ok(req) => self.handle(req),
                    Err(e) => {
                        tracing::error!(error = %e, "task runner: request subscription failed");
                        break;
                    }
                },
            }
        }
    }

    fn handle(&mut self, req: TaskRequest) {
        if req.vehicle_id != self.vehicle_id {
            return self.events.reply(&req, TaskResult::InvalidParameter);
        }
        let (Ok(kind), Ok(source)) = (req.kind(), req.source()) else {
            tracing::warn!(
                kind = req.kind,
                source = req.source,
                "task runner: unknown request"
            );
            return self.events.reply(&req, TaskResult::InvalidParameter);
        };
        tracing::debug!(%kind, %source, id = req.request_id, "task request");
        let link = TaskLink {
            link: self.link.clone(),
            source,
            ack_timeout: Duration::from_millis(u64::from(req.ack_timeout_ms.max(1))),
        };
        let target = flight::geo(&req.target);
        match kind {
            TaskRequestKind::Takeoff | TaskRequestKind::FlyTo => {
                self.preempt_all();
                let spec = TaskSpec::from_request(&req, kind == TaskRequestKind::Takeoff);
                self.task = Some(flight::spawn(link, self.events.clone(), spec, req));
            }
            TaskRequestKind::FlyToStop => match self.running_task() {
                Some(t) => {
                    if let Err(e) = t.control.send(Control::Stop { request: req }) {
                        self.reply_unsent(e.0, TaskResult::NoTask);
                    }
                }
                None => self.events.reply(&req, TaskResult::NoTask),
            },
            TaskRequestKind::FlyToUpdate => match self.running_task() {
                Some(t) => {
                    let c = Control::Update {
                        target,
                        speed_mps: req.speed(),
                        request: req,
                    };
                    if let Err(e) = t.control.send(c) {
                        self.reply_unsent(e.0, TaskResult::NoTask);
                    }
                }
                None => self.events.reply(&req, TaskResult::NoTask),
            },
            TaskRequestKind::PoiEnter => {
                let snap = link.snapshot();
                match poi::enter_check(&snap, monotonic_ns()) {
                    Ok(view) => {
                        self.preempt_all();
                        self.poi = Some(poi_task::spawn(
                            link,
                            self.events.clone(),
                            target,
                            view,
                            req,
                        ));
                    }
                    Err((result, why)) => {
                        tracing::info!(%result, reason = %why, "POI refused: the vehicle cannot orbit now");
                        self.events.publish(poi_task::status_event(
                            &req,
                            None,
                            PoiTaskStatus::Failed,
                            why,
                        ));
                        self.events.reply(&req, result);
                    }
                }
            }
            TaskRequestKind::PoiSpeed | TaskRequestKind::PoiExit => match self.running_poi() {
                Some(p) => {
                    let c = if kind == TaskRequestKind::PoiSpeed {
                        PoiControl::Speed {
                            speed: f64::from(req.speed_mps),
                            request: req,
                        }
                    } else {
                        PoiControl::Exit { request: req }
                    };
                    if let Err(e) = p.control.send(c) {
                        let req = match e.0 {
                            PoiControl::Speed { request, .. } | PoiControl::Exit { request } => {
                                request
                            }
                            PoiControl::Preempt => return,
                        };
                        self.events.reply(&req, TaskResult::WrongState);
                    }
                }
                None => self.events.reply(&req, TaskResult::WrongState),
            },
            TaskRequestKind::PanoStart => self.pano_start(link, req),
            TaskRequestKind::PanoStop => match self.pano.as_ref().filter(|p| p.is_running()) {
                Some(p) => {
                    if let Err(e) = p.control.send(PanoControl::Stop { request: req }) {
                        let PanoControl::Stop { request } = e.0;
                        self.events.reply(&request, TaskResult::NoTask);
                    }
                }
                None => self.events.reply(&req, TaskResult::NoTask),
            },
        }
    }

    /// A panorama from where the gimbal points now, unless one runs.
    fn pano_start(&mut self, link: TaskLink, req: TaskRequest) {
        if self.pano.as_ref().is_some_and(PanoHandle::is_running) {
            tracing::info!("panorama refused: one is running");
            return self.events.reply(&req, TaskResult::WrongState);
        }
        let Some(spec) = PanoSpec::from_request(&req) else {
            tracing::warn!(
                stations = req.pano_stations,
                pitch = req.pano_pitch_deg,
                "panorama refused: no stations"
            );
            return self.events.reply(&req, TaskResult::InvalidParameter);
        };
        let Some(start) = pano_task::gimbal(&link.snapshot()) else {
            tracing::info!(
                "panorama refused: the gimbal attitude is unknown, its stations cannot be checked"
            );
            return self.events.reply(&req, TaskResult::WrongState);
        };
        self.pano = Some(pano_task::spawn(
            link,
            self.events.clone(),
            start,
            spec,
            req,
        ));
    }

    /// A control the task ended before reading: the request's reply.
    fn reply_unsent(&self, c: Control, result: TaskResult) {
        match c {
            Control::Stop { request } | Control::Update { request, .. } => {
                self.events.reply(&request, result)
            }
            Control::Preempt => {}
        }
    }

    fn running_task(&self) -> Option<&TaskHandle> {
        self.task.as_ref().filter(|t| t.is_running())
    }

    fn running_poi(&self) -> Option<&PoiHandle> {
        self.poi.as_ref().filter(|p| p.is_running())
    }

    /// Ends a running task and orbit (they report `Cancelled` / `Ended`).
    fn preempt_all(&mut self) {
        if let Some(t) = self.task.take().filter(TaskHandle::is_running) {
            let _ = t.control.send(Control::Preempt);
        }
        if let Some(p) = self.poi.take().filter(PoiHandle::is_running) {
            let _ = p.control.send(PoiControl::Preempt);
        }
    }
}
