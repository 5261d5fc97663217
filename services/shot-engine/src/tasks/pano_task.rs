//! A panorama sweep as a running task ([`super::pano`] has the plan and the
//! rules): `Gimbal` to each station, wait until `PayloadState` shows it there,
//! `CameraCapture`, a progress event; then back to the start.
//!
//! Events (Pano, under the starting request's id): `InProgress` once started (the
//! reply `Ok` came first) and after each photo; at the end one of:
//!
//! | end | status, result | gimbal |
//! |---|---|---|
//! | every photo taken, back at the start | `Done`, ok (also when the gimbal did not get back: the photos exist; logged) | at the start |
//! | `PanoStop` (replied ok first) | `Stopped`, ok | sent back to the start (not awaited) |
//! | the gimbal does not reach a station within `pano_settle_timeout_ms` | `Failed`, `WrongState` (`VehicleUnavailable` link down, `NoPayloadAuthority` authority lost) | sent back to the start while the authority is the requester's |
//! | payload authority held by another source for [`FAILURE_DEBOUNCE`] | `Failed`, `NoPayloadAuthority` | left to the new holder |
//! | a command refused or unacknowledged | `Failed`, its result (as a reply would have it) | as above |

use std::time::{Duration, Instant};

use skymesh_ipc_types::task::PanoTaskStatus;
use skymesh_ipc_types::{Command, TaskRequest, TaskResult};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use super::link::{Snapshot, TaskLink};
use super::pano::{Aim, Panorama, Stage, SETTLE_TOLERANCE_DEG};
use super::progress::FAILURE_DEBOUNCE;
use super::Events;

/// How often a settling gimbal is looked at.
const SETTLE_POLL: Duration = Duration::from_millis(20);

/// What a PanoStart request asks for, besides the start (the gimbal's own aim).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PanoSpec {
    pub stations: usize,
    pub pitch_deg: f64,
    pub settle_timeout: Duration,
    /// Send `ClearRoi` first: an ROI would hold the gimbal.
    pub clear_roi: bool,
}

impl PanoSpec {
    /// From a PanoStart request; `None` when it asks for no station.
    pub fn from_request(r: &TaskRequest) -> Option<Self> {
        (r.pano_stations > 0 && r.pano_pitch_deg.is_finite()).then(|| PanoSpec {
            stations: usize::from(r.pano_stations),
            pitch_deg: f64::from(r.pano_pitch_deg),
            settle_timeout: Duration::from_millis(u64::from(r.pano_settle_timeout_ms.max(1))),
            clear_roi: r.pano_clear_roi != 0,
        })
    }
}

/// Requests to a running panorama.
#[derive(Debug)]
pub enum PanoControl {
    /// End it (status `Stopped`), reply ok to `request`.
    Stop { request: TaskRequest },
}

/// The runner's side of a running panorama.
#[derive(Debug)]
pub struct PanoHandle {
    pub control: mpsc::UnboundedSender<PanoControl>,
    pub join: JoinHandle<()>,
}

impl PanoHandle {
    pub fn is_running(&self) -> bool {
        !self.join.is_finished()
    }
}

/// The gimbal's aim, if it reports one.
pub fn gimbal(s: &Snapshot) -> Option<Aim> {
    s.payload
        .filter(|p| p.is_gimbal_valid())
        .map(|p| Aim {
            pitch_deg: f64::from(p.gimbal_pitch_deg),
            yaw_deg: f64::from(p.gimbal_yaw_deg),
        })
        .filter(|a| a.pitch_deg.is_finite() && a.yaw_deg.is_finite())
}

/// Starts a panorama from the gimbal at `start` for `request`; the task replies
/// (ok once the gimbal was sent to the first station) and ends by itself.
pub fn spawn(
    link: TaskLink,
    events: Events,
    start: Aim,
    spec: PanoSpec,
    request: TaskRequest,
) -> PanoHandle {
    let (tx, rx) = mpsc::unbounded_channel();
    let pano = Panorama::new(start, spec.stations, spec.pitch_deg);
    let join = tokio::spawn(run(link, events, pano, spec, request, rx));
    PanoHandle { control: tx, join }
}

/// How a panorama ended.
enum End {
    Done,
    Failed(TaskResult),
    Stopped(TaskRequest),
    /// The runner is gone (shutdown): nothing to report to.
    Closed,
}

async fn run(
    link: TaskLink,
    events: Events,
    mut pano: Panorama,
    spec: PanoSpec,
    request: TaskRequest,
    mut control: mpsc::UnboundedReceiver<PanoControl>,
) {
    let Some(first) = pano.target() else { return };
    let mut start = Vec::new();
    if spec.clear_roi {
        start.push(Command::ClearRoi);
    }
    start.push(first.command());
    let r = link.run("pano_start", &start).await;
    events.reply(&request, r);
    if r != TaskResult::Ok {
        return;
    }
    tracing::info!(
        stations = pano.stations().len(),
        start = ?pano.start(),
        "panorama started"
    );
    let event =
        |pano: &Panorama, status, result| events.publish(pano.event(&request, status, result));
    event(&pano, PanoTaskStatus::InProgress, TaskResult::Ok);
    // The gimbal was sent to the first station above.
    let mut sent = true;
    let end = 'run: loop {
        let stage = pano.stage();
        let Some(target) = pano.target() else {
            break End::Done;
        };
        let work = step(&link, spec.settle_timeout, stage, target, sent);
        let result = tokio::select! {
            c = control.recv() => match c {
                None => break 'run End::Closed,
                Some(PanoControl::Stop { request }) => break 'run End::Stopped(request),
            },
            r = work => r,
        };
        match (stage, result) {
            (Stage::Aiming(_), Ok(())) => {
                pano.on_settled();
                sent = false;
            }
            (Stage::Capturing(_), Ok(())) => {
                pano.on_captured();
                event(&pano, PanoTaskStatus::InProgress, TaskResult::Ok);
                sent = false;
            }
            (Stage::Returning, r) => {
                if let Err(result) = r {
                    tracing::warn!(
                        %result,
                        "panorama: the gimbal did not get back to its start (the photos are taken)"
                    );
                }
                pano.on_settled();
            }
            (_, Err(result)) => break End::Failed(result),
            (Stage::Done, Ok(())) => break End::Done,
        }
    };
    match end {
        End::Done => {
            tracing::info!(photos = pano.captured(), "panorama done");
            event(&pano, PanoTaskStatus::Done, TaskResult::Ok);
        }
        End::Failed(result) => {
            tracing::warn!(%result, photos = pano.captured(), "panorama failed");
            if link.snapshot().holds_payload() {
                send_back(&link, &pano);
            }
            event(&pano, PanoTaskStatus::Failed, result);
        }
        End::Stopped(stop) => {
            tracing::info!(photos = pano.captured(), "panorama stopped on request");
            send_back(&link, &pano);
            events.reply(&stop, TaskResult::Ok);
            event(&pano, PanoTaskStatus::Stopped, TaskResult::Ok);
        }
        End::Closed => {}
    }
}

/// One stage's work: reach `target` (sending the gimbal there unless `sent`), or
/// take the station's photo. `Err` holds the result.
async fn step(
    link: &TaskLink,
    settle_timeout: Duration,
    stage: Stage,
    target: Aim,
    sent: bool,
) -> Result<(), TaskResult> {
    match stage {
        Stage::Aiming(_) | Stage::Returning => {
            if !sent {
                let r = link.run("pano", &[target.command()]).await;
                if r != TaskResult::Ok {
                    return Err(r);
                }
            }
            settle(link, target, settle_timeout).await
        }
        Stage::Capturing(_) => match link.run("pano", &[Command::CameraCapture]).await {
            TaskResult::Ok => Ok(()),
            r => Err(r),
        },
        Stage::Done => Ok(()),
    }
}

/// Waits until the gimbal is at `target`, at most `timeout`; fails early when
/// another source has held payload authority for [`FAILURE_DEBOUNCE`].
async fn settle(link: &TaskLink, target: Aim, timeout: Duration) -> Result<(), TaskResult> {
    let deadline = Instant::now() + timeout;
    let mut tick = tokio::time::interval(SETTLE_POLL);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut not_ours: Option<Instant> = None;
    loop {
        tick.tick().await;
        let snap = link.snapshot();
        let aim = gimbal(&snap);
        if aim.is_some_and(|a| target.reached_by(a.pitch_deg, a.yaw_deg, SETTLE_TOLERANCE_DEG)) {
            return Ok(());
        }
        if snap.holds_payload() {
            not_ours = None;
        } else {
            let since = *not_ours.get_or_insert_with(Instant::now);
            if since.elapsed() >= FAILURE_DEBOUNCE {
                return Err(TaskResult::NoPayloadAuthority);
            }
        }
        if Instant::now() >= deadline {
            let result = timeout_result(&snap);
            tracing::warn!(
                target = ?target,
                gimbal = ?aim,
                %result,
                "panorama: the gimbal did not reach the station in time"
            );
            return Err(result);
        }
    }
}

/// Why the gimbal did not get there.
fn timeout_result(snap: &Snapshot) -> TaskResult {
    if !snap.status.is_some_and(|s| s.is_link_up()) {
        TaskResult::VehicleUnavailable
    } else if !snap.holds_payload() {
        TaskResult::NoPayloadAuthority
    } else {
        TaskResult::WrongState
    }
}

/// Points the gimbal back where the panorama started, without waiting.
fn send_back(link: &TaskLink, pano: &Panorama) {
    if let Err(e) = link.send(&pano.start().command(), 0) {
        tracing::warn!(error = %e, "panorama: the gimbal's return not sent");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::{
        AuthorityState, CommandSource, PayloadState, TaskRequestKind, VehicleStatus,
    };

    fn snap(status: Option<VehicleStatus>, authority: Option<AuthorityState>) -> Snapshot {
        Snapshot {
            status,
            authority,
            ..Snapshot::empty(CommandSource::DjiDrc)
        }
    }

    #[test]
    fn a_gimbal_that_never_arrives_is_classified() {
        let ours = AuthorityState {
            payload_holder: CommandSource::DjiDrc.to_wire(),
            ..Default::default()
        };
        let up = VehicleStatus {
            link_up: 1,
            ..Default::default()
        };
        assert_eq!(
            timeout_result(&snap(Some(up), Some(ours))),
            TaskResult::WrongState
        );
        assert_eq!(
            timeout_result(&snap(None, Some(ours))),
            TaskResult::VehicleUnavailable
        );
        assert_eq!(
            timeout_result(&snap(Some(up), None)),
            TaskResult::NoPayloadAuthority
        );
        // Another source's authority is not the requester's.
        let theirs = AuthorityState {
            payload_holder: CommandSource::ShotEngine.to_wire(),
            ..Default::default()
        };
        assert_eq!(
            timeout_result(&snap(Some(up), Some(theirs))),
            TaskResult::NoPayloadAuthority
        );
    }

    #[test]
    fn the_start_is_the_gimbals_own_aim() {
        let mut s = snap(None, None);
        assert_eq!(gimbal(&s), None, "no payload state yet");
        s.payload = Some(PayloadState {
            gimbal_valid: 1,
            gimbal_pitch_deg: -30.0,
            gimbal_yaw_deg: 20.0,
            ..Default::default()
        });
        assert_eq!(
            gimbal(&s),
            Some(Aim {
                pitch_deg: -30.0,
                yaw_deg: 20.0
            })
        );
        s.payload.as_mut().unwrap().gimbal_yaw_deg = f32::NAN;
        assert_eq!(gimbal(&s), None, "not a number");
        s.payload.as_mut().unwrap().gimbal_valid = 0;
        assert_eq!(gimbal(&s), None, "not valid");
    }

    #[test]
    fn a_request_gives_the_plan() {
        let req = TaskRequest {
            kind: TaskRequestKind::PanoStart.to_wire(),
            pano_stations: 8,
            pano_pitch_deg: -10.0,
            pano_settle_timeout_ms: 4000,
            pano_clear_roi: 1,
            ..Default::default()
        };
        assert_eq!(
            PanoSpec::from_request(&req),
            Some(PanoSpec {
                stations: 8,
                pitch_deg: -10.0,
                settle_timeout: Duration::from_secs(4),
                clear_roi: true,
            })
        );
        let none = TaskRequest {
            pano_stations: 0,
            ..req
        };
        assert_eq!(PanoSpec::from_request(&none), None);
        let nan = TaskRequest {
            pano_pitch_deg: f32::NAN,
            ..req
        };
        assert_eq!(PanoSpec::from_request(&nan), None);
    }
}
