//! A panorama capture as a running task ([`crate::pano`] has the plan and the
//! rules): `Gimbal` to each station, wait until `PayloadState` shows it there,
//! `CameraCapture`, a progress event; then back to the start.
//!
//! Events `camera_photo_take_progress`: `in_progress` (current_step 3002,
//! need_reply 0: a lost one is superseded by the next) once started and after each
//! photo; at the end `ok` (3000, 100 %) or `fail` (3000, the percent reached) with
//! need_reply 1, re-sent until the cloud answers.
//!
//! | end | event | gimbal |
//! |---|---|---|
//! | every photo taken, back at the start | `ok`, result 0 (also when the gimbal did not get back: the photos exist; logged) | at the start |
//! | `camera_photo_stop` (replied 0) | `fail`, result 0: stopped on request, not an error | sent back to the start (not awaited) |
//! | the gimbal does not reach a station within `pano_settle_timeout_ms` | `fail`, 314013 (314012 link down, 314010 authority lost) | sent back to the start while the authority is ours |
//! | payload authority held by another source for [`FAILURE_DEBOUNCE`] | `fail`, 314010 | left to the new holder |
//! | a command refused or unacknowledged | `fail`, its code (as a reply would have it) | as above |

use std::time::Instant;

use dji_proto::{codes, Envelope};
use serde_json::json;
use skymesh_ipc_types::Command;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::link::Snapshot;
use crate::pano::{Aim, Panorama, Stage, Status, SETTLE_TOLERANCE_DEG};
use crate::payload::gimbal;
use crate::progress::FAILURE_DEBOUNCE;
use crate::shared::{run_commands, Shared};

const METHOD: &str = "camera_photo_take_progress";

/// Requests to a running panorama.
#[derive(Debug)]
pub enum PanoControl {
    /// camera_photo_stop: end it (status `fail`, result 0), reply 0 to `request`.
    Stop { request: Envelope },
}

/// The services loop's side of a running panorama.
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

/// Starts `pano`; the task replies to `request` (0 with `output.status`
/// `in_progress` once the gimbal was sent to the first station) and ends by itself.
pub fn spawn(shared: Shared, pano: Panorama, clear_roi: bool, request: Envelope) -> PanoHandle {
    let (tx, rx) = mpsc::unbounded_channel();
    let join = tokio::spawn(run(shared, pano, clear_roi, request, rx));
    PanoHandle { control: tx, join }
}

/// How a panorama ended.
enum End {
    Done,
    Failed(u32),
    Stopped(Envelope),
    /// The services loop is gone (shutdown): nothing to report to.
    Closed,
}

async fn run(
    shared: Shared,
    mut pano: Panorama,
    clear_roi: bool,
    request: Envelope,
    mut control: mpsc::UnboundedReceiver<PanoControl>,
) {
    let Some(first) = pano.target() else { return };
    let mut start = Vec::new();
    if clear_roi {
        start.push(Command::ClearRoi);
    }
    start.push(first.command());
    let r = run_commands(&shared.link, "camera_photo_take", &start).await;
    if r != codes::OK {
        shared.emit.reply(request, r);
        return;
    }
    shared
        .emit
        .reply_with_output(request, codes::OK, json!({ "status": "in_progress" }));
    tracing::info!(
        stations = pano.stations().len(),
        start = ?pano.start(),
        "panorama started"
    );
    emit(&shared, &pano, Status::InProgress, codes::OK);
    // The gimbal was sent to the first station above.
    let mut sent = true;
    let end = 'run: loop {
        let stage = pano.stage();
        let Some(target) = pano.target() else {
            break End::Done;
        };
        let work = step(&shared, stage, target, sent);
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
                emit(&shared, &pano, Status::InProgress, codes::OK);
                sent = false;
            }
            (Stage::Returning, r) => {
                if let Err(code) = r {
                    tracing::warn!(
                        result = code,
                        "panorama: the gimbal did not get back to its start (the photos are taken)"
                    );
                }
                pano.on_settled();
            }
            (_, Err(code)) => break End::Failed(code),
            (Stage::Done, Ok(())) => break End::Done,
        }
    };
    match end {
        End::Done => {
            tracing::info!(photos = pano.captured(), "panorama done");
            emit(&shared, &pano, Status::Ok, codes::OK);
        }
        End::Failed(code) => {
            tracing::warn!(result = code, photos = pano.captured(), "panorama failed");
            if shared.link.snapshot().holds_payload() {
                send_back(&shared, &pano);
            }
            emit(&shared, &pano, Status::Fail, code);
        }
        End::Stopped(request) => {
            tracing::info!(photos = pano.captured(), "panorama stopped by the cloud");
            send_back(&shared, &pano);
            shared.emit.reply(request, codes::OK);
            emit(&shared, &pano, Status::Fail, codes::OK);
        }
        End::Closed => {}
    }
}

/// One stage's work: reach `target` (sending the gimbal there unless `sent`), or
/// take the station's photo. `Err` holds the result code.
async fn step(shared: &Shared, stage: Stage, target: Aim, sent: bool) -> Result<(), u32> {
    match stage {
        Stage::Aiming(_) | Stage::Returning => {
            if !sent {
                let r = run_commands(&shared.link, METHOD, &[target.command()]).await;
                if r != codes::OK {
                    return Err(r);
                }
            }
            settle(shared, target).await
        }
        Stage::Capturing(_) => {
            match run_commands(&shared.link, METHOD, &[Command::CameraCapture]).await {
                codes::OK => Ok(()),
                code => Err(code),
            }
        }
        Stage::Done => Ok(()),
    }
}

/// Waits until the gimbal is at `target`, at most `pano_settle_timeout`; fails
/// early when another source has held payload authority for [`FAILURE_DEBOUNCE`].
async fn settle(shared: &Shared, target: Aim) -> Result<(), u32> {
    let deadline = tokio::time::Instant::now() + shared.settings.payload.pano_settle_timeout;
    let mut watch = shared.link.watch();
    let mut not_ours: Option<Instant> = None;
    loop {
        let snap = *watch.borrow_and_update();
        if gimbal(&snap).is_some_and(|(p, y)| target.reached_by(p, y, SETTLE_TOLERANCE_DEG)) {
            return Ok(());
        }
        if snap.holds_payload() {
            not_ours = None;
        } else {
            let since = *not_ours.get_or_insert_with(Instant::now);
            if since.elapsed() >= FAILURE_DEBOUNCE {
                return Err(codes::PAYLOAD_AUTHORITY_REQUIRED);
            }
        }
        match tokio::time::timeout_at(deadline, watch.changed()).await {
            Ok(Ok(())) => {}
            // The bus task ended (shutdown).
            Ok(Err(_)) => return Err(codes::INTERNAL),
            Err(_) => {
                let code = timeout_code(&snap);
                tracing::warn!(
                    target = ?target,
                    gimbal = ?gimbal(&snap),
                    result = code,
                    "panorama: the gimbal did not reach the station in time"
                );
                return Err(code);
            }
        }
    }
}

/// Why the gimbal did not get there, as a result code.
fn timeout_code(snap: &Snapshot) -> u32 {
    if !snap.status.is_some_and(|s| s.is_link_up()) {
        codes::VEHICLE_UNAVAILABLE
    } else if !snap.holds_payload() {
        codes::PAYLOAD_AUTHORITY_REQUIRED
    } else {
        codes::WRONG_STATE
    }
}

/// Points the gimbal back where the panorama started, without waiting.
fn send_back(shared: &Shared, pano: &Panorama) {
    if let Err(e) = shared.link.send(&pano.start().command(), 0) {
        tracing::warn!(error = %e, "panorama: the gimbal's return not sent");
    }
}

fn emit(shared: &Shared, pano: &Panorama, status: Status, result: u32) {
    let need_reply = status != Status::InProgress;
    shared
        .emit
        .event(METHOD, pano.progress(status, result), need_reply);
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::{AuthorityState, CommandSource, VehicleStatus};

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
        let snap = |status, authority| Snapshot {
            status,
            authority,
            ..Default::default()
        };
        assert_eq!(
            timeout_code(&snap(Some(up), Some(ours))),
            codes::WRONG_STATE
        );
        assert_eq!(
            timeout_code(&snap(None, Some(ours))),
            codes::VEHICLE_UNAVAILABLE
        );
        assert_eq!(
            timeout_code(&snap(Some(up), None)),
            codes::PAYLOAD_AUTHORITY_REQUIRED
        );
    }
}
