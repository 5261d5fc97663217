//! Every bus call of digiview-gateway, in one task that owns the three ports.
//!
//! | topic | direction | type | who in the gateway |
//! |---|---|---|---|
//! | `skymesh/vision/state` | subscribe (latest value) | `VisionState` | [`BusTask`] → a `watch` every session reads |
//! | `skymesh/vision/view_control` | publish | `ViewControl` (a SET translated, or CAM_OFFSET's question) | [`BusTask`], for [`BusHandle::call`] |
//! | `skymesh/vision/view_reply` | subscribe | `ViewReply` | [`BusTask`], routed to the waiting session by `request_id` |
//! | `skymesh/vision/demand` | publish | `VisionDemand` | [`BusTask`]: `wanted` while a client is connected (renewed every second), so the pipeline (and the camera) work only then |
//!
//! Read your writes: the pipeline publishes the state that contains a SET's change
//! before its reply, and the bus task takes that state before it hands the reply on,
//! so a GET after the ACKNOWLEDGEMENT reads the new value.
//!
//! Sessions never touch the bus: they read the newest state from the `watch` and
//! send requests through a channel with a oneshot for the answer. Other requesters
//! number their own requests, so replies are matched on `origin == DigiView` as
//! well as `request_id`.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context as _;
use skymesh_ipc_types::{
    topics, view, ViewControl, ViewReply, VisionDemand, VisionOrigin, VisionState,
};
use skymesh_runtime::{Bus, IpcError, Publisher, Subscriber};
use tokio::sync::{mpsc, oneshot, watch};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

/// Requests queued for the bus task.
const CALL_QUEUE: usize = 256;
/// How often the demand word is renewed while a client is connected (the pipeline
/// keeps it for `VISION_DEMAND_LEASE_NS`, 3 s).
const DEMAND_RENEW: Duration = Duration::from_secs(1);

/// The newest `VisionState` and when it arrived.
#[derive(Debug)]
pub struct Latest {
    pub state: Box<VisionState>,
    pub received: Instant,
}

/// One request for the pipeline; the bus task numbers it and answers on `answer`.
#[derive(Debug)]
struct Call {
    control: ViewControl,
    answer: oneshot::Sender<ViewReply>,
}

/// Why a request got no `ViewReply`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CallError {
    #[error("no answer from the vision pipeline within {0:?}")]
    Timeout(Duration),
    #[error("the gateway's bus task has stopped")]
    BusGone,
}

/// What sessions hold: the state `watch` and the way to the bus task. Cheap to clone.
#[derive(Debug, Clone)]
pub struct BusHandle {
    state: watch::Receiver<Option<Arc<Latest>>>,
    calls: mpsc::Sender<Call>,
    clients: Arc<watch::Sender<usize>>,
}

impl BusHandle {
    /// Waits up to `timeout` for the pipeline's first state; true once there is one.
    pub async fn first_state(&self, timeout: Duration) -> bool {
        let mut rx = self.state.clone();
        let got = tokio::time::timeout(timeout, rx.wait_for(|s| s.is_some()))
            .await
            .is_ok_and(|r| r.is_ok());
        got
    }

    /// Sets the number of connected clients (the demand word follows it).
    pub fn set_clients(&self, n: usize) {
        self.clients.send_replace(n);
    }

    /// The newest state if it is younger than `max_age` (else the pipeline is down).
    pub fn fresh_state(&self, max_age: Duration) -> Option<Arc<Latest>> {
        self.state
            .borrow()
            .as_ref()
            .filter(|l| l.received.elapsed() <= max_age)
            .cloned()
    }

    /// Sends one request (its `request_id` and `origin` are the gateway's) and waits
    /// up to `timeout` for the answer.
    pub async fn call(
        &self,
        control: ViewControl,
        timeout: Duration,
    ) -> Result<ViewReply, CallError> {
        let (tx, rx) = oneshot::channel();
        let call = Call {
            control,
            answer: tx,
        };
        let wait = async {
            self.calls
                .send(call)
                .await
                .map_err(|_| CallError::BusGone)?;
            rx.await.map_err(|_| CallError::BusGone)
        };
        tokio::time::timeout(timeout, wait)
            .await
            .unwrap_or(Err(CallError::Timeout(timeout)))
    }
}

/// The task that owns every port.
#[derive(Debug)]
pub struct BusTask {
    control: Publisher<ViewControl>,
    demand: Publisher<VisionDemand>,
    clients: watch::Receiver<usize>,
    states: Subscriber<VisionState>,
    replies: Subscriber<ViewReply>,
    calls: mpsc::Receiver<Call>,
    state_tx: watch::Sender<Option<Arc<Latest>>>,
    /// Sessions waiting for a `ViewReply`, by `request_id`. Entries whose session
    /// gave up (timeout, disconnect) are dropped at the next request.
    pending: HashMap<u64, oneshot::Sender<ViewReply>>,
    last_request: u64,
}

impl BusTask {
    /// Opens the four topics.
    pub fn open(bus: &Bus) -> anyhow::Result<(BusTask, BusHandle)> {
        let (state_tx, state_rx) = watch::channel(None);
        let (calls_tx, calls_rx) = mpsc::channel(CALL_QUEUE);
        let (clients_tx, clients_rx) = watch::channel(0);
        let task = BusTask {
            control: bus
                .publisher::<ViewControl>(&view::view_control())
                .context("opening the view_control topic")?,
            demand: bus
                .publisher::<VisionDemand>(&topics::vision_demand())
                .context("opening the vision_demand topic")?,
            clients: clients_rx,
            states: bus
                .subscriber::<VisionState>(&topics::vision_state())
                .context("opening the vision_state topic")?,
            replies: bus
                .subscriber::<ViewReply>(&view::view_reply())
                .context("opening the view_reply topic")?,
            calls: calls_rx,
            state_tx,
            pending: HashMap::new(),
            last_request: 0,
        };
        Ok((
            task,
            BusHandle {
                state: state_rx,
                calls: calls_tx,
                clients: Arc::new(clients_tx),
            },
        ))
    }

    /// Runs until `stop` (then `Ok`) or a bus failure.
    pub async fn run(self, stop: CancellationToken) -> Result<(), IpcError> {
        let BusTask {
            mut control,
            mut demand,
            mut clients,
            mut states,
            mut replies,
            mut calls,
            state_tx,
            mut pending,
            mut last_request,
        } = self;
        let mut wanted = false;
        let mut renew = tokio::time::interval(DEMAND_RENEW);
        renew.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let word = |demand: &mut Publisher<VisionDemand>, wanted: bool| {
            demand.publish(VisionDemand {
                wanted: u8::from(wanted),
                ..VisionDemand::default()
            })
        };
        let result = loop {
            tokio::select! {
                biased;
                _ = stop.cancelled() => break Ok(()),
                state = states.recv() => {
                    let state = match state {
                        Ok(s) => Box::new(s),
                        Err(e) => break Err(e),
                    };
                    state_tx.send_replace(Some(Arc::new(Latest { state, received: Instant::now() })));
                }
                Ok(()) = clients.changed() => {
                    let now = *clients.borrow_and_update() > 0;
                    if now != wanted {
                        wanted = now;
                        if let Err(e) = word(&mut demand, wanted) {
                            break Err(e);
                        }
                        renew.reset();
                    }
                }
                _ = renew.tick(), if wanted => {
                    if let Err(e) = word(&mut demand, true) {
                        break Err(e);
                    }
                }
                reply = replies.recv() => {
                    let reply = match reply {
                        Ok(r) => r,
                        Err(e) => break Err(e),
                    };
                    // The pipeline published the state that contains this reply's
                    // change before the reply: take it first (read your writes).
                    match states.latest() {
                        Ok(Some(state)) => {
                            state_tx.send_replace(Some(Arc::new(Latest {
                                state: Box::new(state),
                                received: Instant::now(),
                            })));
                        }
                        Ok(None) => {}
                        Err(e) => break Err(e),
                    }
                    let ours = reply.origin == VisionOrigin::DigiView.to_wire();
                    if let Some(tx) = ours.then(|| pending.remove(&reply.request_id)).flatten() {
                        // The session may have given up meanwhile.
                        let _ = tx.send(reply);
                    }
                }
                call = calls.recv() => {
                    // The gateway holds a sender in every handle; None only at the end.
                    let Some(call) = call else { break Ok(()) };
                    pending.retain(|_, tx| !tx.is_closed());
                    last_request = last_request.wrapping_add(1).max(1);
                    let request = ViewControl {
                        request_id: last_request,
                        origin: VisionOrigin::DigiView.to_wire(),
                        ..call.control
                    };
                    if let Err(e) = control.publish(request) {
                        break Err(e);
                    }
                    pending.insert(last_request, call.answer);
                }
            }
        };
        // The pipeline need not wait for the lease to lapse.
        if wanted {
            let _ = word(&mut demand, false);
        }
        result
    }
}
