//! The DRC link (live flight control): a second MQTT connection to the broker that
//! `drc_mode_enter` names, serving `drc/down` (drone_control, drone_emergency_stop,
//! heart_beat) and pushing `drc/up` (replies, osd_info_push, hsi_info_push,
//! delay_info_push).
//!
//! INTERFACE CONTRACT (the services loop codes against this; keep the signatures).
//!
//! | file | role |
//! |---|---|
//! | [`session`] | pure: seq rules, stick freshness, heartbeat timeout, stick → NED setpoint |
//! | [`invalid`] | pure: joystick_invalid_notify onsets |
//! | [`push`] | pure: osd/hsi/delay push data |
//! | [`broker`] | MQTT options, TLS, the first connect, the event-loop driver (reconnects) |
//! | `task` | the async session: messages, timers, acks |
//! | [`metrics`] | `skymesh_dji_drc_*` |
//!
//! States (drc_status_notify): drc_mode_enter → 1 connecting → 2 connected (CONNACK
//! and SUBACK of `drc/down` within `connect_timeout_ms`) or 0 with
//! `DRC_BROKER_UNREACHABLE`. A dropped connection → 1 and reconnects with backoff →
//! 2. DRC mode ends: drc_mode_exit (0, result 0), no heart_beat for
//! `heartbeat_timeout_s` (0, [`DRC_HEARTBEAT_TIMEOUT`]), a failed reconnect after the
//! credentials' `expire_time` (0, `DRC_BROKER_UNREACHABLE`). Leaving brakes the
//! vehicle when the last stick moved it. A second drc_mode_enter replaces the link
//! (no state 0 in between). Flight authority is not released by leaving.

pub mod broker;
pub mod invalid;
#[cfg(test)]
mod invalid_tests;
pub mod metrics;
pub mod push;
pub mod session;
#[cfg(test)]
mod session_tests;
mod task;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use dji_proto::{codes, DrcModeEnter, JoystickInvalidReason};
use serde::Deserialize;
use skymesh_runtime::{CancellationToken, Stats};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::link::VehicleLink;
use metrics::DrcMetrics;

/// drc_status_notify `result` when DRC mode ends because no heart_beat came for
/// `heartbeat_timeout_s` (state 0).
pub use dji_proto::codes::DRC_HEARTBEAT_TIMEOUT;

/// How long exit/replace waits for the session task to brake and disconnect.
const STOP_GRACE: Duration = Duration::from_secs(3);

/// `[drc]` of the gateway's config. Every key optional (defaults below).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DrcConfig {
    /// Freshness limit of the stick stream, ms: no drone_control for longer → brake
    /// to hover; the next one gets 319034. Also the setpoints' max age. 100..=2000.
    pub stick_max_age_ms: u32,
    /// No heart_beat for longer than this → leave DRC mode. 5..=600 s.
    pub heartbeat_timeout_s: u32,
    /// How long drc_mode_enter waits for the DRC broker (CONNACK + SUBACK), ms.
    /// 100..=60000.
    pub connect_timeout_ms: u32,
    /// PEM CA bundle used when drc_mode_enter asks for TLS (`enable_tls`).
    pub ca_file: Option<std::path::PathBuf>,
    /// First reconnect delay after the DRC connection drops, ms (doubling per
    /// failure, each delay drawn from [d/2, d]). 50..=60000.
    pub reconnect_initial_ms: u32,
    /// Longest reconnect delay, ms. reconnect_initial_ms..=300000.
    pub reconnect_max_ms: u32,
    /// A return or landing with the battery at or below this percentage is a low
    /// battery failsafe for joystick_invalid_notify (reasons 1 and 2). 0..=100.
    pub low_battery_pct: u8,
    /// Larger drc/down payloads are dropped unparsed (malformed `oversized`): a
    /// drone_control is ~150 bytes. 256..=65536.
    pub max_payload_bytes: u32,
    /// drc/down messages per second (and burst) handled; the excess is dropped
    /// unparsed (malformed `rate_limited`). The cloud sends sticks at 5..=10 Hz
    /// plus a heart_beat per second. 1..=1000.
    pub max_messages_per_s: u32,
}

impl Default for DrcConfig {
    fn default() -> Self {
        DrcConfig {
            stick_max_age_ms: 500,
            heartbeat_timeout_s: 60,
            connect_timeout_ms: 5000,
            ca_file: None,
            reconnect_initial_ms: 200,
            reconnect_max_ms: 5000,
            low_battery_pct: 20,
            max_payload_bytes: 4096,
            max_messages_per_s: 50,
        }
    }
}

impl DrcConfig {
    /// Range checks; the message names the key.
    pub fn validate(&self) -> Result<(), String> {
        let range = |key: &str, v: u32, lo: u32, hi: u32| {
            if (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(format!("{key} = {v} is outside {lo}..={hi}"))
            }
        };
        range("stick_max_age_ms", self.stick_max_age_ms, 100, 2000)?;
        range("heartbeat_timeout_s", self.heartbeat_timeout_s, 5, 600)?;
        range("connect_timeout_ms", self.connect_timeout_ms, 100, 60_000)?;
        range(
            "reconnect_initial_ms",
            self.reconnect_initial_ms,
            50,
            60_000,
        )?;
        range(
            "reconnect_max_ms",
            self.reconnect_max_ms,
            self.reconnect_initial_ms,
            300_000,
        )?;
        range("low_battery_pct", self.low_battery_pct.into(), 0, 100)?;
        range("max_payload_bytes", self.max_payload_bytes, 256, 65_536)?;
        range("max_messages_per_s", self.max_messages_per_s, 1, 1000)?;
        if let Some(ca) = &self.ca_file {
            crate::tls::load_roots(ca).map_err(|e| format!("ca_file: {e}"))?;
        }
        Ok(())
    }
}

/// What the DRC link tells the services loop (which publishes the events).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DrcNotice {
    /// drc_status_notify: 0 not connected, 1 connecting, 2 connected; result 0 or
    /// the reason of a failure/exit.
    State { drc_state: u8, result: u32 },
    /// joystick_invalid_notify (only while in DRC mode).
    JoystickInvalid(JoystickInvalidReason),
}

/// The running session task.
#[derive(Debug)]
struct Running {
    stop: CancellationToken,
    stop_reason: Arc<OnceLock<&'static str>>,
    alive: Arc<AtomicBool>,
    task: JoinHandle<()>,
}

/// The DRC mode of one gateway. Holding it costs nothing; a session runs as its
/// own task between `enter` and `exit` (or until it leaves by itself).
#[derive(Debug)]
pub struct Drc {
    config: DrcConfig,
    gateway_sn: String,
    link: VehicleLink,
    metrics: DrcMetrics,
    notices: mpsc::UnboundedSender<DrcNotice>,
    shutdown: CancellationToken,
    running: Option<Running>,
}

impl Drc {
    pub fn new(
        config: DrcConfig,
        gateway_sn: String,
        link: VehicleLink,
        stats: Stats,
        notices: mpsc::UnboundedSender<DrcNotice>,
        shutdown: CancellationToken,
    ) -> Drc {
        let metrics = DrcMetrics::new(&stats);
        metrics.state.set(0.0);
        Drc {
            config,
            gateway_sn,
            link,
            metrics,
            notices,
            shutdown,
            running: None,
        }
    }

    fn notify(&self, drc_state: u8, result: u32) {
        self.metrics.state.set(f64::from(drc_state));
        let _ = self.notices.send(DrcNotice::State { drc_state, result });
    }

    /// drc_mode_enter: connect to `req.mqtt_broker` (replacing a current DRC link),
    /// subscribe `drc/down`, start the pushes; the `result` for services_reply
    /// (0 once connected and subscribed, else a dji_proto::codes value).
    pub async fn enter(&mut self, req: &DrcModeEnter) -> u32 {
        self.stop_running("replaced").await;
        if self.shutdown.is_cancelled() {
            return codes::INTERNAL;
        }
        self.notify(1, codes::OK);
        let entered = tokio::time::Instant::now().into_std();
        let expiry = broker::expiry(req.mqtt_broker.expire_time, entered, broker::unix_now());
        let connected = tokio::select! {
            _ = self.shutdown.cancelled() => None,
            r = broker::connect(&self.config, &self.gateway_sn, &req.mqtt_broker) => Some(r),
        };
        let conn = match connected {
            Some(Ok(conn)) => conn,
            Some(Err(e)) => {
                tracing::warn!(
                    address = %req.mqtt_broker.address,
                    client_id = %req.mqtt_broker.client_id,
                    tls = req.mqtt_broker.enable_tls,
                    error = %e,
                    "DRC: cannot reach the DRC broker"
                );
                self.metrics.exit("connect_failed");
                self.notify(0, codes::DRC_BROKER_UNREACHABLE);
                return codes::DRC_BROKER_UNREACHABLE;
            }
            None => {
                // Shutting down: nobody to tell.
                self.metrics.state.set(0.0);
                return codes::INTERNAL;
            }
        };
        tracing::info!(
            address = %req.mqtt_broker.address,
            client_id = %req.mqtt_broker.client_id,
            tls = req.mqtt_broker.enable_tls,
            osd_hz = req.osd_frequency,
            hsi_hz = req.hsi_frequency,
            "DRC: connected to the DRC broker, drc/down subscribed"
        );
        // State 2 goes out before the task can report a drop.
        self.notify(2, codes::OK);
        let stop = self.shutdown.child_token();
        let stop_reason = Arc::new(OnceLock::new());
        let alive = Arc::new(AtomicBool::new(true));
        let task = tokio::spawn(task::run(task::Start {
            config: self.config.clone(),
            link: self.link.clone(),
            metrics: self.metrics.clone(),
            notices: self.notices.clone(),
            alive: alive.clone(),
            conn,
            osd_hz: req.osd_frequency,
            hsi_hz: req.hsi_frequency,
            expiry,
            stop: stop.clone(),
            stop_reason: stop_reason.clone(),
        }));
        self.running = Some(Running {
            stop,
            stop_reason,
            alive,
            task,
        });
        codes::OK
    }

    /// drc_mode_exit: brake if sticks were active, disconnect, state 0. The result
    /// (codes::DRC_STATE when not in DRC mode).
    pub async fn exit(&mut self) -> u32 {
        if !self.is_active() {
            // A session that left by itself has told the loop already.
            self.stop_running("exit").await;
            return codes::DRC_STATE;
        }
        self.stop_running("exit").await;
        self.notify(0, codes::OK);
        codes::OK
    }

    /// In DRC mode (connected or reconnecting), as of now.
    pub fn is_active(&self) -> bool {
        self.running
            .as_ref()
            .is_some_and(|r| r.alive.load(Ordering::Acquire))
    }

    /// Stops the session task (it brakes if needed and disconnects) and waits for it.
    async fn stop_running(&mut self, reason: &'static str) {
        let Some(running) = self.running.take() else {
            return;
        };
        let _ = running.stop_reason.set(reason);
        running.stop.cancel();
        let abort = running.task.abort_handle();
        if tokio::time::timeout(STOP_GRACE, running.task)
            .await
            .is_err()
        {
            tracing::warn!("DRC: the session task did not stop in time; aborted");
            abort.abort();
        }
    }
}

impl Drop for Drc {
    fn drop(&mut self) {
        if let Some(running) = &self.running {
            let _ = running.stop_reason.set("dropped");
            running.stop.cancel();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_ranges_name_their_key() {
        DrcConfig::default().validate().unwrap();
        let bad = |c: DrcConfig| c.validate().unwrap_err();
        let d = DrcConfig::default;
        assert!(bad(DrcConfig {
            stick_max_age_ms: 99,
            ..d()
        })
        .contains("stick_max_age_ms"));
        assert!(bad(DrcConfig {
            max_payload_bytes: 100,
            ..d()
        })
        .contains("max_payload_bytes"));
        assert!(bad(DrcConfig {
            max_messages_per_s: 0,
            ..d()
        })
        .contains("max_messages_per_s"));
        assert!(bad(DrcConfig {
            stick_max_age_ms: 2001,
            ..d()
        })
        .contains("stick_max_age_ms"));
        assert!(bad(DrcConfig {
            heartbeat_timeout_s: 4,
            ..d()
        })
        .contains("heartbeat_timeout_s"));
        assert!(bad(DrcConfig {
            heartbeat_timeout_s: 601,
            ..d()
        })
        .contains("heartbeat_timeout_s"));
        assert!(bad(DrcConfig {
            connect_timeout_ms: 0,
            ..d()
        })
        .contains("connect_timeout_ms"));
        assert!(bad(DrcConfig {
            reconnect_initial_ms: 10,
            ..d()
        })
        .contains("reconnect_initial_ms"));
        assert!(bad(DrcConfig {
            reconnect_max_ms: 100,
            ..d()
        })
        .contains("reconnect_max_ms"));
        assert!(bad(DrcConfig {
            low_battery_pct: 101,
            ..d()
        })
        .contains("low_battery_pct"));
        assert!(bad(DrcConfig {
            ca_file: Some("/nonexistent.pem".into()),
            ..d()
        })
        .contains("ca_file"));
    }

    #[test]
    fn the_config_section_parses_with_every_key_optional() {
        let c: DrcConfig = toml_like(r#"{"stick_max_age_ms": 300}"#);
        assert_eq!(c.stick_max_age_ms, 300);
        assert_eq!(c.heartbeat_timeout_s, 60);
        let unknown: Result<DrcConfig, _> = serde_json::from_str(r#"{"nope": 1}"#);
        assert!(unknown.is_err(), "unknown keys are refused");
    }

    fn toml_like(json: &str) -> DrcConfig {
        serde_json::from_str(json).expect("parses")
    }
}
