//! Every bus call of digiview-gateway, in one task that owns the three ports.
//!
//! | topic | direction | type | who in the gateway |
//! |---|---|---|---|
//! | `skymesh/vision/state` | subscribe (latest value) | `VisionState` | [`BusTask`] → a `watch` every session reads |
//! | `skymesh/vision/control` | publish | `VisionControl` (`DigiViewSet`) | [`BusTask`], for [`BusHandle::set`] |
//! | `skymesh/vision/reply` | subscribe | `VisionReply` | [`BusTask`], routed to the waiting session by `request_id` |
//!
//! Sessions never touch the bus: they read the newest state from the `watch` and
//! send SETs through a channel with a oneshot for the answer. Other requesters
//! (autopilot-link) number their own requests, so replies are matched on
//! `origin == DigiView` and `kind == DigiViewSet` as well as `request_id`.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context as _;
use digiview_proto::DATA_LEN;
use skymesh_ipc_types::{
    topics, VisionControl, VisionControlKind, VisionOrigin, VisionReply, VisionState,
};
use skymesh_runtime::{Bus, IpcError, Publisher, Subscriber};
use tokio::sync::{mpsc, oneshot, watch};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

/// SETs queued for the bus task.
const CALL_QUEUE: usize = 256;

/// The newest `VisionState` and when it arrived.
#[derive(Debug)]
pub struct Latest {
    pub state: Box<VisionState>,
    pub received: Instant,
}

/// One SET for the pipeline; the bus task answers on `answer`.
#[derive(Debug)]
struct SetCall {
    param: u8,
    data: [u8; DATA_LEN],
    answer: oneshot::Sender<VisionReply>,
}

/// Why a SET got no `VisionReply`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SetError {
    #[error("no answer from the vision pipeline within {0:?}")]
    Timeout(Duration),
    #[error("the gateway's bus task has stopped")]
    BusGone,
}

/// What sessions hold: the state `watch` and the way to the bus task. Cheap to clone.
#[derive(Debug, Clone)]
pub struct BusHandle {
    state: watch::Receiver<Option<Arc<Latest>>>,
    calls: mpsc::Sender<SetCall>,
}

impl BusHandle {
    /// The newest state if it is younger than `max_age` (else the pipeline is down).
    pub fn fresh_state(&self, max_age: Duration) -> Option<Arc<Latest>> {
        self.state
            .borrow()
            .as_ref()
            .filter(|l| l.received.elapsed() <= max_age)
            .cloned()
    }

    /// Forwards one checked DigiView SET and waits up to `timeout` for the answer.
    pub async fn set(
        &self,
        param: u8,
        data: [u8; DATA_LEN],
        timeout: Duration,
    ) -> Result<VisionReply, SetError> {
        let (tx, rx) = oneshot::channel();
        let call = SetCall {
            param,
            data,
            answer: tx,
        };
        let wait = async {
            self.calls.send(call).await.map_err(|_| SetError::BusGone)?;
            rx.await.map_err(|_| SetError::BusGone)
        };
        tokio::time::timeout(timeout, wait)
            .await
            .unwrap_or(Err(SetError::Timeout(timeout)))
    }
}

/// The task that owns every port.
#[derive(Debug)]
pub struct BusTask {
    control: Publisher<VisionControl>,
    states: Subscriber<VisionState>,
    replies: Subscriber<VisionReply>,
    calls: mpsc::Receiver<SetCall>,
    state_tx: watch::Sender<Option<Arc<Latest>>>,
    /// Sessions waiting for a `VisionReply`, by `request_id`. Entries whose session
    /// gave up (timeout, disconnect) are dropped at the next SET.
    pending: HashMap<u64, oneshot::Sender<VisionReply>>,
    last_request: u64,
}

impl BusTask {
    /// Opens the three topics.
    pub fn open(bus: &Bus) -> anyhow::Result<(BusTask, BusHandle)> {
        let (state_tx, state_rx) = watch::channel(None);
        let (calls_tx, calls_rx) = mpsc::channel(CALL_QUEUE);
        let task = BusTask {
            control: bus
                .publisher::<VisionControl>(&topics::vision_control())
                .context("opening the vision_control topic")?,
            states: bus
                .subscriber::<VisionState>(&topics::vision_state())
                .context("opening the vision_state topic")?,
            replies: bus
                .subscriber::<VisionReply>(&topics::vision_reply())
                .context("opening the vision_reply topic")?,
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
            },
        ))
    }

    /// Runs until `stop` (then `Ok`) or a bus failure.
    pub async fn run(self, stop: CancellationToken) -> Result<(), IpcError> {
        let BusTask {
            mut control,
            mut states,
            mut replies,
            mut calls,
            state_tx,
            mut pending,
            mut last_request,
        } = self;
        loop {
            tokio::select! {
                biased;
                _ = stop.cancelled() => return Ok(()),
                state = states.recv() => {
                    let state = Box::new(state?);
                    state_tx.send_replace(Some(Arc::new(Latest { state, received: Instant::now() })));
                }
                reply = replies.recv() => {
                    let reply = reply?;
                    let ours = reply.origin == VisionOrigin::DigiView.to_wire()
                        && reply.kind == VisionControlKind::DigiViewSet.to_wire();
                    if let Some(tx) = ours.then(|| pending.remove(&reply.request_id)).flatten() {
                        // The session may have given up meanwhile.
                        let _ = tx.send(reply);
                    }
                }
                call = calls.recv() => {
                    // The gateway holds a sender in every handle; None only at the end.
                    let Some(call) = call else { return Ok(()) };
                    pending.retain(|_, tx| !tx.is_closed());
                    last_request = last_request.wrapping_add(1).max(1);
                    let request = VisionControl {
                        request_id: last_request,
                        kind: VisionControlKind::DigiViewSet.to_wire(),
                        origin: VisionOrigin::DigiView.to_wire(),
                        param: call.param,
                        data: call.data,
                        ..VisionControl::default()
                    };
                    control.publish(request)?;
                    pending.insert(last_request, call.answer);
                }
            }
        }
    }
}
