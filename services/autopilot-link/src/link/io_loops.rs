//! A connection's reader (bytes → frames → hub and service events, by socket
//! readiness or a polling thread) and its writer loop.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{MavHeader, Message};
use tokio::io::unix::AsyncFd;
use tokio::io::Interest;
use tokio::sync::mpsc;

use crate::hub::Hub;
use crate::metrics::Metrics;
use crate::router::{AckLedger, AckOwner};
use crate::transport::{self, Received};
use mavlink_frame::{message_info, FrameParser, RawFrame};

use super::outbox::{Outgoing, SendContext};
use super::{LinkEvent, Outbox, READ_BUFFER};

pub(super) fn lock_ledger(ledger: &Mutex<AckLedger>) -> MutexGuard<'_, AckLedger> {
    ledger.lock().unwrap_or_else(PoisonError::into_inner)
}

/// What the reader does with the bytes it read, however it waited for them: split
/// them into frames, route every frame to the endpoints, and decode the ones for
/// the service.
pub(super) struct Intake<'a> {
    parser: FrameParser,
    last_message: Instant,
    metrics: &'a Metrics,
    hub: &'a Hub,
    ledger: &'a Mutex<AckLedger>,
    /// Decoded messages of the last read, handed to the service in one go after
    /// every frame of the read was routed (so a batch of telemetry wakes the
    /// service once, not once per message with routing in between).
    out: Vec<(MavHeader, MavMessage)>,
}

impl<'a> Intake<'a> {
    pub(super) fn new(metrics: &'a Metrics, hub: &'a Hub, ledger: &'a Mutex<AckLedger>) -> Self {
        Intake {
            parser: FrameParser::new(),
            last_message: Instant::now(),
            metrics,
            hub,
            ledger,
            out: Vec::new(),
        }
    }

    /// Takes one read; the messages for the service are then in `self.out`.
    pub(super) fn take(&mut self, bytes: &[u8], datagram: bool) {
        self.parser.push(bytes);
        while let Some(frame) = self.parser.next_frame() {
            self.last_message = Instant::now();
            self.hub.from_autopilot(&frame);
            if let Some(msg) = decode_for_service(&frame, self.metrics, self.ledger) {
                self.out.push((frame.header(), msg));
            }
        }
        if datagram {
            self.parser.end_datagram();
        }
        let bad = self.parser.take_malformed();
        if bad > 0 {
            self.hub.autopilot_malformed(bad);
        }
    }

    pub(super) fn silent_for(&self, silence: Option<Duration>) -> Option<String> {
        let silence = silence?;
        (self.last_message.elapsed() >= silence)
            .then(|| format!("no MAVLink received for {silence:?}"))
    }
}

/// Reads a serial port until it fails, the stop flag is set or the service is gone
/// (a blocking thread; sockets are read by [`read_socket`]).
pub(super) fn read_loop(
    reader: &mut transport::Reader,
    silence: Option<Duration>,
    events: &mpsc::Sender<LinkEvent>,
    metrics: &Metrics,
    hub: &Hub,
    ledger: &Mutex<AckLedger>,
    stop: &AtomicBool,
) -> String {
    let mut buf = vec![0u8; READ_BUFFER];
    let mut intake = Intake::new(metrics, hub, ledger);
    while !stop.load(Ordering::Relaxed) {
        match reader.read(&mut buf) {
            Ok(Received::Stream(n)) => intake.take(&buf[..n], false),
            Ok(Received::Datagram(n)) => intake.take(&buf[..n], true),
            Ok(Received::Idle) => {
                if let Some(reason) = intake.silent_for(silence) {
                    return reason;
                }
                continue;
            }
            Ok(Received::Closed) => return "closed by the other end".to_string(),
            Err(e) => return format!("read failed: {e}"),
        }
        for (header, msg) in intake.out.drain(..) {
            if events
                .blocking_send(LinkEvent::Message(header, msg))
                .is_err()
            {
                return "service stopped".to_string();
            }
        }
    }
    "stopped".to_string()
}

/// Reads a TCP or UDP socket from tokio's reactor until it fails or the service is
/// gone (ends early when dropped). Compared with a reader thread, a datagram costs
/// one wake-up of the runtime's thread, which then also runs the service, instead
/// of the reader thread's wake-up plus the one it hands the messages to.
pub(super) async fn read_socket(
    socket: transport::SocketReader,
    silence: Option<Duration>,
    events: &mpsc::Sender<LinkEvent>,
    metrics: &Metrics,
    hub: &Hub,
    ledger: &Mutex<AckLedger>,
) -> String {
    // `AsyncFd::new` is deprecated because it cannot prove the descriptor stays open
    // while registered; here the `AsyncFd` owns the socket, so it does.
    #[allow(deprecated)]
    let mut fd = match AsyncFd::with_interest(socket, Interest::READABLE) {
        Ok(fd) => fd,
        Err(e) => return format!("cannot wait on the socket: {e}"),
    };
    let mut buf = vec![0u8; READ_BUFFER];
    let mut intake = Intake::new(metrics, hub, ledger);
    // Looked at once per `silence` (not re-armed per message); no timer without one.
    let check = tokio::time::sleep(silence.unwrap_or_default());
    tokio::pin!(check);
    loop {
        let mut ready = tokio::select! {
            r = fd.readable_mut() => match r {
                Ok(guard) => guard,
                Err(e) => return format!("waiting on the socket failed: {e}"),
            },
            () = &mut check, if silence.is_some() => {
                if let Some(reason) = intake.silent_for(silence) {
                    return reason;
                }
                let next = intake.last_message + silence.unwrap_or_default();
                check.as_mut().reset(next.into());
                continue;
            }
        };
        match ready.get_inner_mut().read_now(&mut buf) {
            Ok(Received::Stream(n)) => {
                // A short read emptied the stream's receive queue: what arrives
                // later raises a new edge, so the `recv` that would only return
                // EAGAIN is skipped (tokio's own TcpStream does the same).
                if n < buf.len() {
                    ready.clear_ready();
                }
                intake.take(&buf[..n], false)
            }
            Ok(Received::Datagram(n)) => intake.take(&buf[..n], true),
            Ok(Received::Idle) => {
                ready.clear_ready();
                continue;
            }
            Ok(Received::Closed) => return "closed by the other end".to_string(),
            Err(e) => return format!("read failed: {e}"),
        }
        drop(ready);
        for (header, msg) in intake.out.drain(..) {
            if events.send(LinkEvent::Message(header, msg)).await.is_err() {
                return "service stopped".to_string();
            }
        }
    }
}

/// Decodes a frame from the autopilot for the service: `None` for frames that are
/// not for it (not in our dialect, unparsable, an endpoint's COMMAND_ACK).
pub(super) fn decode_for_service(
    frame: &RawFrame,
    metrics: &Metrics,
    ledger: &Mutex<AckLedger>,
) -> Option<MavMessage> {
    let id = frame.message_id();
    // Not in our dialect: forwarded to the endpoints, nothing for us.
    message_info(id)?;
    let msg = match frame.decode() {
        Ok(msg) => msg,
        Err(e) => {
            metrics.parse_errors.inc();
            tracing::debug!(error = %e, message_id = id, "unparsable MAVLink frame");
            return None;
        }
    };
    metrics.received(msg.message_name());
    if let MavMessage::COMMAND_ACK(ack) = &msg {
        let command = ack.command as u16;
        let target = (ack.target_system, ack.target_component);
        let owner = lock_ledger(ledger).on_ack(command, ack.result as u8, target, Instant::now());
        if owner == AckOwner::Endpoint {
            tracing::debug!(
                command,
                ?target,
                "COMMAND_ACK for a router endpoint; not ours"
            );
            return None;
        }
    }
    Some(msg)
}

/// The writer thread: writes what the [`Outbox`] hands it until the outbox closes
/// or a write fails.
pub(super) fn write_loop(
    writer: &mut transport::Writer,
    outbox: &Outbox,
    ctx: &SendContext,
    stop: &AtomicBool,
) -> String {
    while !stop.load(Ordering::Relaxed) {
        match outbox.next() {
            Some(Outgoing::Own(msg, sequence)) => {
                let frame = ctx.encode(&msg, sequence);
                if let Err(e) = writer.write_frame(frame.as_bytes()) {
                    return format!("write failed: {e}");
                }
                ctx.written(msg.message_name(), &frame);
            }
            Some(Outgoing::Rest(p)) => {
                let rest = p.frame.as_bytes().get(p.written..).unwrap_or_default();
                if let Err(e) = writer.write_frame(rest) {
                    return format!("write failed: {e}");
                }
                ctx.written(p.name, &p.frame);
            }
            Some(Outgoing::Forwarded(frame)) => {
                if let Some(command) = frame.command() {
                    lock_ledger(&ctx.ledger).sent(command, false, Instant::now());
                }
                if let Err(e) = writer.write_frame(frame.as_bytes()) {
                    return format!("write failed: {e}");
                }
                ctx.hub.forwarded_to_autopilot();
            }
            // Closed: the connection is ending.
            None => break,
        }
    }
    "stopped".to_string()
}
