//! The event loop's side of gimbal protocol v2 ([`crate::gimbal_v2`]): the vision
//! pipeline's state and replies in, `VisionControl` out, frames from endpoints
//! addressed to the virtual gimbals in (through the router hub's local inbox), and
//! their telemetry and acks out to every endpoint (never to the autopilot).
//!
//! | metric | labels |
//! |---|---|
//! | `skymesh_autopilot_gimbal_v2_total` | `msg` (set_attitude, set_pitchyaw, pitchyaw, configure, roi_location, roi_none, zoom, request_message, unsupported_command, payload, undecodable, component_collision), `outcome` (accepted, denied, unsupported, failed, temporarily_rejected, not_in_control, invalid, seen) |

use std::sync::Arc;
use std::time::{Duration, Instant};

use mavlink::MavHeader;
use skymesh_ipc_types::{Command, VisionControl, VisionReply, VisionState};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{CounterFamily, IpcError, Publisher, Stats, Subscriber, WarnLimiter};
use tokio::sync::mpsc;

use super::Service;
use crate::gimbal_v2::{GimbalV2, Incoming, Output, VisionSettings};
use crate::hub::Hub;
use crate::Lifecycle;
use mavlink_frame::RawFrame;

/// Frames waiting for the virtual gimbals; beyond this the hub drops them (counted).
pub const INBOX: usize = 128;

/// The bus ports and router inbox of the virtual gimbals.
pub(crate) struct VisionPorts {
    /// The pipeline's state (history 1).
    pub state: Subscriber<VisionState>,
    /// Requests to the pipeline; each is answered on `reply`.
    pub control: Publisher<VisionControl>,
    /// Every requester's replies: ours are matched by request id.
    pub reply: Subscriber<VisionReply>,
    /// Frames from endpoints addressed to the virtual gimbals (filled by the [`Hub`]).
    pub inbox: mpsc::Receiver<RawFrame>,
}

/// What woke the vision side.
pub(crate) enum VisionWake {
    /// Boxed: a state is several kilobytes.
    State(Result<Box<VisionState>, IpcError>),
    Reply(Result<VisionReply, IpcError>),
    Frame(Option<RawFrame>),
}

pub(crate) struct Vision {
    ports: VisionPorts,
    gimbals: GimbalV2,
    hub: Arc<Hub>,
    system: u8,
    /// Sequence number per virtual component.
    sequence: [u8; 256],
    forward_payload: bool,
    counts: CounterFamily,
    warn: WarnLimiter<&'static str>,
}

/// A request-id seed that differs between runs (process id and wall time), so a
/// restarted autopilot-link never matches replies meant for its predecessor.
fn seed() -> u64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    (u64::from(std::process::id()) << 40) ^ nanos
}

impl Vision {
    pub fn new(
        settings: &VisionSettings,
        system: u8,
        ports: VisionPorts,
        hub: Arc<Hub>,
        stats: &Stats,
    ) -> Vision {
        Vision {
            gimbals: GimbalV2::new(system, settings, seed(), monotonic_ns()),
            ports,
            hub,
            system,
            sequence: [0; 256],
            forward_payload: settings.forward_payload,
            counts: CounterFamily::new(
                stats,
                "skymesh_autopilot_gimbal_v2_total",
                ("msg", Some("outcome")),
            ),
            warn: WarnLimiter::default(),
        }
    }

    /// Waits for the next state, reply or frame; never if `vision` is `None`.
    pub async fn next(vision: Option<&mut Vision>) -> VisionWake {
        let Some(v) = vision else {
            return std::future::pending().await;
        };
        tokio::select! {
            s = v.ports.state.recv() => VisionWake::State(s.map(Box::new)),
            r = v.ports.reply.recv() => VisionWake::Reply(r),
            f = v.ports.inbox.recv() => VisionWake::Frame(f),
        }
    }

    /// `None`: nothing due until a sample or frame arrives.
    fn deadline(&self) -> Option<Instant> {
        let now_ns = monotonic_ns();
        let due = self.gimbals.next_deadline_ns(now_ns);
        (due != u64::MAX).then(|| Instant::now() + Duration::from_nanos(due.saturating_sub(now_ns)))
    }

    /// Sends, publishes, counts and logs what the gimbals produced.
    fn flush(&mut self, out: Output) -> anyhow::Result<()> {
        for (component, msg) in out.sends {
            let seq = &mut self.sequence[usize::from(component)];
            let header = MavHeader {
                system_id: u32::from(self.system),
                component_id: component,
                sequence: *seq,
            };
            *seq = seq.wrapping_add(1);
            self.hub.from_local(&RawFrame::encode(header, &msg));
        }
        for c in out.controls {
            self.ports.control.publish(c)?;
        }
        for (msg, outcome) in out.counts {
            self.counts.get(msg, outcome).inc();
        }
        let now = Instant::now();
        for (key, text) in out.warnings {
            match self.warn.allow(key, now) {
                Some(hidden) => tracing::warn!(hidden, "gimbal v2: {text}"),
                None => tracing::debug!("gimbal v2: {text}"),
            }
        }
        Ok(())
    }
}

impl<L: Lifecycle> Service<L> {
    pub(super) fn on_vision(&mut self, wake: VisionWake) -> anyhow::Result<()> {
        let status = self.telemetry.status(self.link.is_up(), None);
        let home = (status.home_valid == 1).then_some(status.home_alt_msl_m);
        let Some(v) = self.vision.as_mut() else {
            return Ok(());
        };
        let mut out = Output::default();
        match wake {
            VisionWake::State(s) => v.gimbals.on_state(s?.as_ref()),
            VisionWake::Reply(r) => v.gimbals.on_reply(&r?, &mut out),
            VisionWake::Frame(None) => {
                return Err(anyhow::anyhow!("the virtual gimbals' inbox closed"))
            }
            VisionWake::Frame(Some(frame)) => match frame.decode() {
                Ok(msg) => v.gimbals.handle(
                    Incoming {
                        from: (frame.system_id(), frame.component_id()),
                        msg: &msg,
                    },
                    home,
                    monotonic_ns(),
                    &mut out,
                ),
                Err(e) => {
                    out.counts.push(("undecodable", "invalid"));
                    out.warnings.push((
                        "undecodable",
                        format!("frame for a virtual gimbal not decoded: {e}"),
                    ));
                }
            },
        }
        v.flush(out)
    }

    /// Telemetry and reply timeouts.
    pub(super) fn poll_vision(&mut self) -> anyhow::Result<()> {
        let Some(v) = self.vision.as_mut() else {
            return Ok(());
        };
        let mut out = Output::default();
        v.gimbals.poll(monotonic_ns(), &mut out);
        v.flush(out)
    }

    pub(super) fn vision_deadline(&self) -> Option<Instant> {
        self.vision.as_ref().and_then(Vision::deadline)
    }

    /// An accepted camera/gimbal command also goes to the virtual cameras.
    pub(super) fn forward_to_vision(&mut self, command: &Command) -> anyhow::Result<()> {
        let Some(v) = self.vision.as_mut().filter(|v| v.forward_payload) else {
            return Ok(());
        };
        let mut out = Output::default();
        if v.gimbals
            .forward_payload(command, monotonic_ns(), &mut out)
            .is_some()
        {
            v.flush(out)?;
        }
        Ok(())
    }

    /// A message heard on the autopilot link from one of our virtual components'
    /// ids: a real component is being shadowed.
    pub(super) fn check_collision(&mut self, header: &MavHeader) -> anyhow::Result<()> {
        let Some(v) = self.vision.as_mut() else {
            return Ok(());
        };
        if header.system_id != u32::from(v.system)
            || v.gimbals.cam_of(header.component_id).is_none()
        {
            return Ok(());
        }
        let out = Output {
            counts: vec![("component_collision", "seen")],
            warnings: vec![(
                "component_collision",
                format!(
                    "component {} behind the autopilot uses a virtual gimbal's id: ground \
                     stations cannot reach it; choose other [vision] components",
                    header.component_id
                ),
            )],
            ..Output::default()
        };
        v.flush(out)
    }
}
