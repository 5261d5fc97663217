//! The async side of one DRC session: `drc/down` messages from the broker driver,
//! the timers (stick freshness and heartbeat via [`Session::next_deadline`], the
//! osd/hsi/delay pushes), the vehicle samples and arbiter events for
//! joystick_invalid_notify, and the command acknowledgements. Every decision is the
//! pure code's ([`super::session`], [`super::invalid`], [`super::push`]); this file
//! only moves bytes and keeps time.
//!
//! The hot path (drone_control → `VehicleCommand`) never waits for an ack: the
//! setpoint is published at once and the reply goes out; the ack is awaited in a
//! spawned task and comes back here for the metrics and delay_info_push.

use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::task::{Context, Poll, Waker};
use std::time::{Duration, Instant};

use dji_proto::{
    codes, encode_drc_up, parse_drc, parse_envelope, DrcDown, DroneControl, Envelope,
    JoystickInvalidReason, Reject, TopicKind,
};
use rumqttc::{AsyncClient, QoS};
use serde_json::{json, Value};
use skymesh_ipc_types::{AckResult, ArbiterEvent, Command, CommandAck, FlightMode};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{CancellationToken, TokenBucket, WarnLimiter};
use tokio::sync::{broadcast, mpsc};
use tokio::time::MissedTickBehavior;

use super::broker::{self, BackoffLimits, Connected, LinkEvent};
use super::invalid::{reason_name, InvalidWatch};
use super::metrics::DrcMetrics;
use super::push::{self, DelayMeter};
use super::session::{Due, Session, SessionLimits, StickDecision, VehicleView};
use super::{DrcConfig, DrcNotice, DRC_HEARTBEAT_TIMEOUT};
use crate::link::{CommandFailure, VehicleLink};

/// drc/up replies: QoS 2, as the reference implementation answers (FACTS.md).
const REPLY_QOS: QoS = QoS::ExactlyOnce;
/// Pushes are periodic state: a lost one is replaced by the next (QoS 0).
const PUSH_QOS: QoS = QoS::AtMostOnce;
/// How long leaving waits for the driver to send DISCONNECT.
const DRIVER_GRACE: Duration = Duration::from_secs(1);
/// Link events buffered between the driver and the session.
const LINK_EVENTS: usize = 256;

/// Everything one session task needs.
#[derive(Debug)]
pub(super) struct Start {
    pub config: DrcConfig,
    pub link: VehicleLink,
    pub metrics: DrcMetrics,
    pub notices: mpsc::UnboundedSender<DrcNotice>,
    /// Cleared when the session ends (by itself or by its owner).
    pub alive: Arc<AtomicBool>,
    pub conn: Connected,
    pub osd_hz: u8,
    pub hsi_hz: u8,
    /// The credentials of drc_mode_enter expire here.
    pub expiry: Instant,
    /// The owner's stop (drc_mode_exit, a new drc_mode_enter, shutdown).
    pub stop: CancellationToken,
    /// Why the owner stopped it (metrics); unset = shutdown.
    pub stop_reason: Arc<OnceLock<&'static str>>,
}

/// Why a session ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Leave {
    /// By its owner; the owner tells the services loop.
    Owner(&'static str),
    HeartbeatTimeout,
    CredentialsExpired,
    SubscribeRefused,
    DriverEnded,
}

impl Leave {
    fn reason(self) -> &'static str {
        match self {
            Leave::Owner(r) => r,
            Leave::HeartbeatTimeout => "heartbeat_timeout",
            Leave::CredentialsExpired => "credentials_expired",
            Leave::SubscribeRefused => "subscribe_refused",
            Leave::DriverEnded => "driver_ended",
        }
    }

    /// The drc_status_notify result when the session leaves by itself.
    fn code(self) -> Option<u32> {
        match self {
            Leave::Owner(_) => None,
            Leave::HeartbeatTimeout => Some(DRC_HEARTBEAT_TIMEOUT),
            Leave::CredentialsExpired | Leave::SubscribeRefused | Leave::DriverEnded => {
                Some(codes::DRC_BROKER_UNREACHABLE)
            }
        }
    }
}

/// What an acknowledgement answers.
#[derive(Debug, Clone, Copy)]
enum AckFor {
    /// A stick setpoint from a drone_control that arrived at this instant.
    Stick {
        arrived: Instant,
    },
    SetMode,
    EmergencyStop,
}

#[derive(Debug)]
struct AckReport {
    what: AckFor,
    result: Result<CommandAck, CommandFailure>,
    at: Instant,
}

fn now() -> Instant {
    tokio::time::Instant::now().into_std()
}

fn now_ms() -> u64 {
    u64::try_from(broker::unix_now().as_millis()).unwrap_or(u64::MAX)
}

fn push_interval(hz: u8) -> tokio::time::Interval {
    let mut i = tokio::time::interval(Duration::from_secs_f64(1.0 / f64::from(hz.max(1))));
    i.set_missed_tick_behavior(MissedTickBehavior::Skip);
    i
}

/// The metrics label of a drc/down method.
fn method_label(method: &str) -> &'static str {
    match method {
        "drone_control" => "drone_control",
        "drone_emergency_stop" => "drone_emergency_stop",
        "heart_beat" => "heart_beat",
        _ => "unknown",
    }
}

/// The `seq` of a rejected message, when one is readable (`data.seq`, else top-level).
fn readable_seq(env: &Envelope) -> Option<i64> {
    env.data.get("seq").and_then(Value::as_i64).or(env.seq)
}

struct Task {
    config: DrcConfig,
    link: VehicleLink,
    metrics: DrcMetrics,
    notices: mpsc::UnboundedSender<DrcNotice>,
    alive: Arc<AtomicBool>,
    client: AsyncClient,
    up: String,
    session: Session,
    invalid: InvalidWatch,
    delay: DelayMeter,
    /// Connected and subscribed (pushes go out).
    connected: bool,
    expiry: Instant,
    acks: mpsc::UnboundedSender<AckReport>,
    warnings: WarnLimiter<&'static str>,
    /// `max_messages_per_s` of drc/down.
    rate: TokenBucket,
}

/// The edge checks of one drc/down payload before it is parsed: its size, then the
/// rate. `Err` is the malformed reason it is dropped and counted under.
fn admit(
    payload_len: usize,
    max_payload_bytes: u32,
    rate: &mut TokenBucket,
    now: Instant,
) -> Result<(), &'static str> {
    if payload_len > max_payload_bytes as usize {
        return Err("oversized");
    }
    if !rate.take(now) {
        return Err("rate_limited");
    }
    Ok(())
}

/// Runs one session until its owner stops it or it leaves by itself.
pub(super) async fn run(start: Start) {
    let Start {
        config,
        link,
        metrics,
        notices,
        alive,
        conn,
        osd_hz,
        hsi_hz,
        expiry,
        stop,
        stop_reason,
    } = start;
    let (link_tx, mut link_rx) = mpsc::channel(LINK_EVENTS);
    let driver_stop = CancellationToken::new();
    let client = conn.client.clone();
    let up = conn.up.clone();
    let backoff = BackoffLimits {
        initial: Duration::from_millis(config.reconnect_initial_ms.into()),
        max: Duration::from_millis(config.reconnect_max_ms.into()),
    };
    let driver = tokio::spawn(broker::drive(conn, backoff, link_tx, driver_stop.clone()));
    let (acks, mut acks_rx) = mpsc::unbounded_channel();
    let limits = SessionLimits {
        stick_max_age: Duration::from_millis(config.stick_max_age_ms.into()),
        heartbeat_timeout: Duration::from_secs(config.heartbeat_timeout_s.into()),
    };
    let mut vehicle = link.watch();
    let mut arbiter = link.arbiter_events();
    let rate = TokenBucket::new(config.max_messages_per_s, config.max_messages_per_s, now());
    let mut task = Task {
        invalid: InvalidWatch::new(config.low_battery_pct),
        session: Session::new(limits, now()),
        config,
        link,
        metrics,
        notices,
        alive,
        client,
        up,
        delay: DelayMeter::default(),
        connected: true,
        expiry,
        acks,
        warnings: WarnLimiter::default(),
        rate,
    };
    let (mut osd, mut hsi, mut delay) = (
        push_interval(osd_hz),
        push_interval(hsi_hz),
        push_interval(1),
    );
    let (mut vehicle_open, mut arbiter_open) = (true, true);
    task.check_vehicle();
    let leave = loop {
        let deadline = tokio::time::Instant::from_std(task.session.next_deadline());
        tokio::select! {
            biased;
            _ = stop.cancelled() => {
                break Leave::Owner(stop_reason.get().copied().unwrap_or("shutdown"));
            }
            event = link_rx.recv() => match event {
                Some(event) => if let Some(leave) = task.on_link_event(event) { break leave },
                None => break Leave::DriverEnded,
            },
            Some(report) = acks_rx.recv() => task.on_ack(report),
            _ = tokio::time::sleep_until(deadline) => {}
            _ = osd.tick() => task.push_osd(),
            _ = hsi.tick() => task.push_hsi(),
            _ = delay.tick() => {
                task.push_delay();
                // Sample ages grow without new samples: re-read the link condition.
                task.check_vehicle();
            }
            changed = vehicle.changed(), if vehicle_open => match changed {
                Ok(()) => task.check_vehicle(),
                Err(_) => vehicle_open = false,
            },
            event = arbiter.recv(), if arbiter_open => match event {
                Ok(event) => task.on_arbiter_event(&event),
                Err(broadcast::error::RecvError::Lagged(_)) => {}
                Err(broadcast::error::RecvError::Closed) => arbiter_open = false,
            },
        }
        if let Some(leave) = task.poll_due() {
            break leave;
        }
    };
    task.leave(leave);
    driver_stop.cancel();
    let abort = driver.abort_handle();
    if tokio::time::timeout(DRIVER_GRACE, driver).await.is_err() {
        abort.abort();
    }
}

impl Task {
    fn notify(&self, notice: DrcNotice) {
        // The services loop gone means the gateway is stopping; nothing to tell.
        let _ = self.notices.send(notice);
    }

    fn set_state(&self, drc_state: u8, result: u32) {
        self.metrics.state.set(f64::from(drc_state));
        self.notify(DrcNotice::State { drc_state, result });
    }

    /// The stick stream or the heartbeat timed out?
    fn poll_due(&mut self) -> Option<Leave> {
        match self.session.poll(now())? {
            Due::Brake => {
                tracing::info!("DRC: stick stream stale; braking (next drone_control: 319034)");
                self.brake("stale");
                None
            }
            Due::HeartbeatTimeout => Some(Leave::HeartbeatTimeout),
        }
    }

    fn brake(&self, reason: &'static str) {
        self.metrics.brake(reason);
        if let Err(e) = self.link.send(&Command::Brake, 0) {
            tracing::warn!(error = %e, reason, "DRC: could not send the brake");
        }
    }

    fn leave(&mut self, why: Leave) {
        self.alive.store(false, Ordering::Release);
        if self.session.sticks_active() {
            self.brake(why.reason());
        }
        self.metrics.exit(why.reason());
        if let Some(code) = why.code() {
            tracing::warn!(
                reason = why.reason(),
                result = code,
                "DRC: leaving DRC mode"
            );
            self.set_state(0, code);
        } else {
            tracing::info!(reason = why.reason(), "DRC: session ended");
        }
    }

    fn on_link_event(&mut self, event: LinkEvent) -> Option<Leave> {
        match event {
            LinkEvent::Message { publish, at } => {
                if let Some(leave) = self.poll_due() {
                    return Some(leave);
                }
                self.on_message(&publish.payload, at);
            }
            LinkEvent::Up => {
                self.connected = true;
                self.metrics.reconnects.inc();
                tracing::info!("DRC: broker connection back");
                self.set_state(2, codes::OK);
            }
            LinkEvent::Down { failures, error } => {
                self.metrics.connection_errors.inc();
                if failures == 1 {
                    self.connected = false;
                    tracing::warn!(%error, "DRC: broker connection lost; reconnecting");
                    self.set_state(1, codes::OK);
                } else if now() >= self.expiry {
                    tracing::warn!(%error, "DRC: reconnect failed and the credentials have expired");
                    return Some(Leave::CredentialsExpired);
                } else if let Some(hidden) = self.warnings.allow("reconnect", now()) {
                    tracing::warn!(%error, failures, hidden, "DRC: reconnect failed");
                }
            }
            LinkEvent::SubscribeRefused => return Some(Leave::SubscribeRefused),
        }
        None
    }

    fn on_message(&mut self, payload: &[u8], at: Instant) {
        if let Err(reason) = admit(
            payload.len(),
            self.config.max_payload_bytes,
            &mut self.rate,
            now(),
        ) {
            self.metrics.malformed(reason);
            if let Some(hidden) = self.warnings.allow(reason, now()) {
                tracing::warn!(
                    reason,
                    bytes = payload.len(),
                    max_payload_bytes = self.config.max_payload_bytes,
                    max_messages_per_s = self.config.max_messages_per_s,
                    hidden,
                    "DRC: dropped a drc/down payload unparsed"
                );
            }
            return;
        }
        let env = match parse_envelope(TopicKind::DrcDown, payload) {
            Ok(env) => env,
            Err(e) => {
                self.metrics.malformed(e.kind());
                if let Some(hidden) = self.warnings.allow("malformed", now()) {
                    tracing::warn!(error = %e, hidden, "DRC: dropped a drc/down payload");
                }
                return;
            }
        };
        match parse_drc(&env) {
            Ok(DrcDown::DroneControl(stick)) => self.drone_control(&stick, at),
            Ok(DrcDown::DroneEmergencyStop) => self.emergency_stop(),
            Ok(DrcDown::HeartBeat { seq, timestamp }) => {
                self.session.heart_beat(now());
                self.metrics.heartbeats.inc();
                self.metrics.message("heart_beat", codes::OK);
                self.reply("heart_beat", json!({ "seq": seq, "timestamp": timestamp }));
            }
            Err(reject) => self.rejected(&env, &reject),
        }
    }

    fn rejected(&mut self, env: &Envelope, reject: &Reject) {
        self.metrics.message(method_label(&env.method), reject.code);
        if let Some(hidden) = self.warnings.allow("rejected", now()) {
            tracing::warn!(method = %env.method, error = %reject, hidden, "DRC: refused a drc/down message");
        }
        let mut data = json!({ "result": reject.code });
        if let Some(seq) = readable_seq(env) {
            data["output"] = json!({ "seq": seq });
        }
        self.reply(&env.method, data);
    }

    fn drone_control(&mut self, stick: &DroneControl, arrived: Instant) {
        let view = VehicleView::from_snapshot(&self.link.snapshot(), monotonic_ns());
        let result = match self.session.drone_control(now(), stick, &view) {
            StickDecision::Refuse(code) => code,
            StickDecision::Fly {
                set_guided,
                setpoint,
            } => {
                if set_guided {
                    tracing::info!(mode = ?view.mode, "DRC: sticks move the vehicle: switching to GUIDED");
                    if let Err(e) =
                        self.send_tracked(Command::SetMode(FlightMode::Guided), 0, AckFor::SetMode)
                    {
                        tracing::warn!(error = %e, "DRC: could not request GUIDED");
                    }
                }
                let max_age = self.config.stick_max_age_ms;
                match self.send_tracked(setpoint, max_age, AckFor::Stick { arrived }) {
                    Ok(()) => codes::OK,
                    Err(e) => {
                        self.metrics.stick(failure_label(&e));
                        if let Some(hidden) = self.warnings.allow("stick_send", now()) {
                            tracing::warn!(error = %e, hidden, "DRC: stick setpoint not published");
                        }
                        match e {
                            CommandFailure::Invalid(_) => codes::INTERNAL,
                            _ => codes::VEHICLE_UNAVAILABLE,
                        }
                    }
                }
            }
        };
        self.metrics.message("drone_control", result);
        self.reply(
            "drone_control",
            json!({ "result": result, "output": { "seq": stick.seq } }),
        );
    }

    /// drone_emergency_stop: an emergency stop engaged under our own source
    /// (`dji_drc`), so the arbiter counts the DJI pilot among its engagers. The DJI
    /// Cloud API has no method that releases it (drone_emergency_stop has no
    /// counterpart, and a later drone_control is a stick input, not a release): it
    /// is never withdrawn from here, and only an operator's or safety's
    /// `ClearEmergency` ends it. Stick commands meanwhile are refused by the arbiter.
    fn emergency_stop(&mut self) {
        tracing::warn!("DRC: drone_emergency_stop");
        self.session.emergency_stop();
        self.invalid.emergency_stop_sent(now());
        if let Err(e) = self.send_tracked(Command::EmergencyStop, 0, AckFor::EmergencyStop) {
            tracing::error!(error = %e, "DRC: emergency stop not published");
            self.answer_emergency_stop(codes::EMERGENCY_STOP_FAILED);
        }
    }

    fn answer_emergency_stop(&self, result: u32) {
        self.metrics.message("drone_emergency_stop", result);
        self.reply("drone_emergency_stop", json!({ "result": result }));
    }

    /// Publishes `command` now and routes its ack back to [`Task::on_ack`] without
    /// waiting: the ack-awaiting future is polled once here, which publishes the
    /// sample synchronously (so commands leave in the order they were decided),
    /// and then finishes in its own task. Bus and validation failures are returned.
    fn send_tracked(
        &self,
        command: Command,
        max_age_ms: u32,
        what: AckFor,
    ) -> Result<(), CommandFailure> {
        let link = self.link.clone();
        let mut pending = Box::pin(async move { link.command(&command, max_age_ms).await });
        let mut cx = Context::from_waker(Waker::noop());
        match pending.as_mut().poll(&mut cx) {
            Poll::Ready(Err(e @ (CommandFailure::Invalid(_) | CommandFailure::Bus(_)))) => Err(e),
            Poll::Ready(result) => {
                let _ = self.acks.send(AckReport {
                    what,
                    result,
                    at: now(),
                });
                Ok(())
            }
            Poll::Pending => {
                let acks = self.acks.clone();
                // The spawned task polls again with its own waker before anything
                // can complete unseen.
                tokio::spawn(async move {
                    let result = pending.await;
                    let _ = acks.send(AckReport {
                        what,
                        result,
                        at: now(),
                    });
                });
                Ok(())
            }
        }
    }

    fn on_ack(&mut self, report: AckReport) {
        let AckReport { what, result, at } = report;
        match what {
            AckFor::Stick { arrived } => {
                let label = match &result {
                    Ok(ack) if ack.result() == Some(AckResult::Limited) => "limited",
                    Ok(_) => "accepted",
                    Err(e) => failure_label(e),
                };
                self.metrics.stick(label);
                if matches!(result, Ok(_) | Err(CommandFailure::Refused(_))) {
                    let latency = at.saturating_duration_since(arrived);
                    self.delay.record(latency);
                    self.metrics.latency.observe(latency.as_secs_f64());
                }
                if let Err(e) = &result {
                    if let Some(hidden) = self.warnings.allow("stick_refused", now()) {
                        tracing::warn!(error = %e, hidden, "DRC: stick setpoint not executed");
                    }
                }
            }
            AckFor::SetMode => {
                if let Err(e) = result {
                    tracing::warn!(error = %e, "DRC: GUIDED refused");
                }
            }
            AckFor::EmergencyStop => match result {
                Ok(_) => self.answer_emergency_stop(codes::OK),
                Err(e) => {
                    tracing::error!(error = %e, "DRC: emergency stop failed");
                    self.answer_emergency_stop(codes::EMERGENCY_STOP_FAILED);
                }
            },
        }
    }

    fn reply(&self, method: &str, data: Value) {
        let bytes = encode_drc_up(method, data, None, now_ms());
        if let Err(e) = self
            .client
            .try_publish(self.up.clone(), REPLY_QOS, false, bytes)
        {
            self.metrics.reply_dropped.inc();
            tracing::debug!(error = %e, method, "DRC: reply not queued");
        }
    }

    fn push(&self, method: &'static str, data: Option<Value>) {
        let Some(data) = data.filter(|_| self.connected) else {
            self.metrics.push_dropped(method);
            return;
        };
        let bytes = encode_drc_up(method, data, None, now_ms());
        match self
            .client
            .try_publish(self.up.clone(), PUSH_QOS, false, bytes)
        {
            Ok(()) => self.metrics.push(method),
            Err(_) => self.metrics.push_dropped(method),
        }
    }

    fn push_osd(&self) {
        let data = push::osd(&self.link.snapshot()).and_then(|o| serde_json::to_value(o).ok());
        self.push("osd_info_push", data);
    }

    fn push_hsi(&self) {
        self.push("hsi_info_push", serde_json::to_value(push::hsi()).ok());
    }

    fn push_delay(&mut self) {
        let data = serde_json::to_value(self.delay.take()).ok();
        self.push("delay_info_push", data);
    }

    fn check_vehicle(&mut self) {
        let snap = self.link.snapshot();
        for reason in self.invalid.on_vehicle(now(), &snap, monotonic_ns()) {
            self.joystick_invalid(reason);
        }
    }

    fn on_arbiter_event(&mut self, event: &ArbiterEvent) {
        if let Some(reason) = self.invalid.on_arbiter_event(now(), event) {
            self.joystick_invalid(reason);
        }
    }

    fn joystick_invalid(&self, reason: JoystickInvalidReason) {
        tracing::info!(reason = reason_name(reason), "DRC: joystick invalid");
        self.metrics.joystick_invalid(reason_name(reason));
        self.notify(DrcNotice::JoystickInvalid(reason));
    }
}

/// The stick-metrics label of a failure.
fn failure_label(e: &CommandFailure) -> &'static str {
    match e {
        CommandFailure::Invalid(_) => "invalid",
        CommandFailure::Bus(_) => "bus_error",
        CommandFailure::NoAck(_) => "no_ack",
        CommandFailure::Refused(_) => "refused",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(method: &str, data: Value, seq: Option<i64>) -> Envelope {
        Envelope {
            tid: String::new(),
            bid: String::new(),
            timestamp: 0,
            gateway: None,
            method: method.into(),
            data,
            need_reply: None,
            seq,
        }
    }

    #[test]
    fn a_seq_is_read_where_it_can_be() {
        assert_eq!(
            readable_seq(&env("drone_control", json!({"seq": 4, "x": "a"}), None)),
            Some(4)
        );
        assert_eq!(
            readable_seq(&env("drone_control", json!({"x": 1}), Some(9))),
            Some(9)
        );
        assert_eq!(
            readable_seq(&env("drone_control", json!({"seq": "4"}), None)),
            None
        );
        assert_eq!(readable_seq(&env("drone_control", Value::Null, None)), None);
    }

    #[test]
    fn method_labels_are_bounded() {
        assert_eq!(method_label("heart_beat"), "heart_beat");
        assert_eq!(method_label("x".repeat(1000).as_str()), "unknown");
    }

    #[test]
    fn oversized_and_flooding_payloads_are_refused_before_parsing() {
        let t0 = Instant::now();
        let mut rate = TokenBucket::new(10, 10, t0);
        assert_eq!(admit(4097, 4096, &mut rate, t0), Err("oversized"));
        assert_eq!(
            rate.available(t0),
            10,
            "an oversized payload costs no token"
        );
        assert!((0..10).all(|_| admit(150, 4096, &mut rate, t0).is_ok()));
        assert_eq!(admit(150, 4096, &mut rate, t0), Err("rate_limited"));
        // 10 per second: one more after 100 ms.
        let later = t0 + Duration::from_millis(100);
        assert_eq!(admit(150, 4096, &mut rate, later), Ok(()));
        assert_eq!(admit(150, 4096, &mut rate, later), Err("rate_limited"));
    }

    #[test]
    fn leaving_by_itself_says_why() {
        assert_eq!(Leave::Owner("exit").code(), None);
        assert_eq!(Leave::HeartbeatTimeout.code(), Some(DRC_HEARTBEAT_TIMEOUT));
        assert_eq!(
            Leave::CredentialsExpired.code(),
            Some(codes::DRC_BROKER_UNREACHABLE)
        );
    }
}
