//! What the services loop hands to the tasks it starts (flight tasks, POI, payload
//! and authority jobs): the settings, the vehicle link, and the [`Emitter`] through
//! which every reply and event goes back to the loop (which owns the MQTT outbox).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use dji_proto::{codes, Envelope};
use serde::Serialize;
use serde_json::Value;
use skymesh_ipc_types::{AuthorityDomain, Command, RefusalReason};
use tokio::sync::mpsc;

use crate::config::Settings;
use crate::link::{CommandFailure, VehicleLink};

/// A message for the cloud, produced anywhere, published by the loop.
#[derive(Debug, Clone, PartialEq)]
pub enum Outgoing {
    /// `services_reply` to `request` with `data.result` (and `data.output` when
    /// given: camera_photo_take's `{"status": "in_progress"}` of a panorama).
    Reply {
        request: Envelope,
        result: u32,
        output: Option<Value>,
    },
    /// An `events` message with fresh tid/bid.
    Event {
        method: &'static str,
        data: Value,
        need_reply: bool,
    },
}

/// Sends [`Outgoing`] messages to the loop. Cheap to clone; sending never blocks
/// (the loop bounds what it keeps for the broker).
#[derive(Debug, Clone)]
pub struct Emitter(mpsc::UnboundedSender<Outgoing>);

impl Emitter {
    pub fn new() -> (Emitter, mpsc::UnboundedReceiver<Outgoing>) {
        let (tx, rx) = mpsc::unbounded_channel();
        (Emitter(tx), rx)
    }

    pub fn reply(&self, request: Envelope, result: u32) {
        // The loop outlives every task; a closed channel means we are shutting down.
        let _ = self.0.send(Outgoing::Reply {
            request,
            result,
            output: None,
        });
    }

    /// A reply carrying `data.output` too.
    pub fn reply_with_output(&self, request: Envelope, result: u32, output: Value) {
        let _ = self.0.send(Outgoing::Reply {
            request,
            result,
            output: Some(output),
        });
    }

    pub fn event(&self, method: &'static str, data: impl Serialize, need_reply: bool) {
        match serde_json::to_value(data) {
            Ok(data) => {
                let _ = self.0.send(Outgoing::Event {
                    method,
                    data,
                    need_reply,
                });
            }
            Err(e) => tracing::error!(method, error = %e, "cannot serialise an event"),
        }
    }
}

/// Authorities the cloud grabbed and the gateway keeps alive (re-sent grabs) until
/// another source takes them.
#[derive(Debug, Default)]
pub struct Keep {
    pub flight: AtomicBool,
    pub payload: AtomicBool,
}

impl Keep {
    pub fn set(&self, domain: AuthorityDomain, on: bool) {
        match domain {
            AuthorityDomain::Flight => self.flight.store(on, Ordering::Relaxed),
            AuthorityDomain::Payload => self.payload.store(on, Ordering::Relaxed),
        }
    }

    pub fn get(&self, domain: AuthorityDomain) -> bool {
        match domain {
            AuthorityDomain::Flight => self.flight.load(Ordering::Relaxed),
            AuthorityDomain::Payload => self.payload.load(Ordering::Relaxed),
        }
    }
}

/// Everything a task needs. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Shared {
    pub settings: Arc<Settings>,
    pub link: VehicleLink,
    pub emit: Emitter,
    pub keep: Arc<Keep>,
}

/// The result code for a command that did not succeed.
pub fn failure_code(f: &CommandFailure, command: &Command) -> u32 {
    let domain = command.kind().authority();
    match f {
        CommandFailure::Invalid(_) => codes::OUT_OF_RANGE,
        CommandFailure::Bus(_) => codes::INTERNAL,
        CommandFailure::NoAck(_) => codes::VEHICLE_UNAVAILABLE,
        CommandFailure::Refused(ack) => match ack.reason() {
            Some(RefusalReason::NoAuthority | RefusalReason::Preempted) => match domain {
                Some(AuthorityDomain::Payload) => codes::PAYLOAD_AUTHORITY_REQUIRED,
                _ => codes::FLIGHT_AUTHORITY_REQUIRED,
            },
            Some(RefusalReason::LinkDown | RefusalReason::Timeout) => codes::VEHICLE_UNAVAILABLE,
            Some(RefusalReason::WrongState) => codes::WRONG_STATE,
            Some(RefusalReason::InvalidParameter) => codes::OUT_OF_RANGE,
            Some(RefusalReason::Unsupported) if domain == Some(AuthorityDomain::Payload) => {
                codes::PAYLOAD_UNSUPPORTED
            }
            _ => codes::REFUSED_BY_ARBITER,
        },
    }
}

/// Sends `commands` one after the other, each after the previous one's acceptance:
/// 0 when all were accepted, else the first failure's code (logged).
pub async fn run_commands(link: &VehicleLink, method: &str, commands: &[Command]) -> u32 {
    for c in commands {
        if let Err(f) = link.command(c, 0).await {
            let code = failure_code(&f, c);
            tracing::info!(method, command = ?c.kind(), error = %f, result = code, "command not accepted");
            return code;
        }
    }
    codes::OK
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::{AckResult, CommandAck, CommandError};
    use std::time::Duration;

    fn refused(reason: RefusalReason) -> CommandFailure {
        CommandFailure::Refused(CommandAck {
            result: AckResult::Refused.to_wire(),
            reason: reason.to_wire(),
            ..Default::default()
        })
    }

    #[test]
    fn failures_map_to_documented_codes() {
        let goto = Command::Brake;
        let zoom = Command::CameraCapture;
        assert_eq!(
            failure_code(&refused(RefusalReason::NoAuthority), &goto),
            codes::FLIGHT_AUTHORITY_REQUIRED
        );
        assert_eq!(
            failure_code(&refused(RefusalReason::NoAuthority), &zoom),
            codes::PAYLOAD_AUTHORITY_REQUIRED
        );
        assert_eq!(
            failure_code(&refused(RefusalReason::Unsupported), &zoom),
            codes::PAYLOAD_UNSUPPORTED
        );
        assert_eq!(
            failure_code(&refused(RefusalReason::Unsupported), &goto),
            codes::REFUSED_BY_ARBITER
        );
        assert_eq!(
            failure_code(&refused(RefusalReason::Geofence), &goto),
            codes::REFUSED_BY_ARBITER
        );
        assert_eq!(
            failure_code(&refused(RefusalReason::LinkDown), &goto),
            codes::VEHICLE_UNAVAILABLE
        );
        assert_eq!(
            failure_code(&refused(RefusalReason::WrongState), &goto),
            codes::WRONG_STATE
        );
        assert_eq!(
            failure_code(&CommandFailure::NoAck(Duration::from_secs(1)), &goto),
            codes::VEHICLE_UNAVAILABLE
        );
        assert_eq!(
            failure_code(
                &CommandFailure::Invalid(CommandError::NotFinite { name: "x" }),
                &goto
            ),
            codes::OUT_OF_RANGE
        );
        assert_eq!(
            failure_code(&CommandFailure::Bus("x".into()), &goto),
            codes::INTERNAL
        );
    }
}
