//! Every `services` request, after `parse_service`: the checks all methods share
//! ([`precheck`], pure), then the method's execution — immediate, or a task that
//! replies when its commands were acknowledged.
//!
//! Checks, in order (the first failure is the reply):
//! 1. `gateway`, when present, must be our `gateway_sn` → else `NOT_IN_ENUM`
//!    (a one-value enum: the request is addressed to another device).
//! 2. `payload_index`, when the method has one, must be the configured one →
//!    else `UNKNOWN_PAYLOAD`.
//! 3. Authority: flight methods (takeoff, flyto, POI) need the flight authority the
//!    cloud grabbed → else `FLIGHT_AUTHORITY_REQUIRED` (319030); payload methods
//!    need payload authority → else `PAYLOAD_AUTHORITY_REQUIRED`. Payload methods
//!    that turn the aircraft (camera_look_at, locked aim and drag) need both.
//!
//! While a panorama runs (asked of the shot engine's task runner, [`crate::pano`])
//! it owns the camera and gimbal: camera_photo_stop ends it, every other payload
//! method (a second camera_photo_take too) is refused `WRONG_STATE`.

use std::sync::{Arc, Mutex as StdMutex};
use std::time::Duration;

use dji_proto::{codes, Envelope, ServiceRequest};
use skymesh_ipc_types::{AuthorityDomain, Command};
use tokio::sync::Mutex;

use crate::config::Settings;
use crate::drc::Drc;
use crate::link::Snapshot;
use crate::payload::{self, PayloadMemory, Plan};
use crate::progress::Heights;
use crate::shared::{failure_code, run_commands, Shared};
use crate::tasks::{task_point, TaskClient};

/// Which authority a method needs before anything is sent.
pub fn authority_needed(req: &ServiceRequest) -> Option<AuthorityDomain> {
    use ServiceRequest as S;
    match req {
        S::TakeoffToPoint(_)
        | S::FlyToPoint(_)
        | S::FlyToPointStop
        | S::FlyToPointUpdate(_)
        | S::PoiModeEnter { .. }
        | S::PoiModeExit
        | S::PoiCircleSpeedSet { .. } => Some(AuthorityDomain::Flight),
        S::FlightAuthorityGrab
        | S::PayloadAuthorityGrab { .. }
        | S::DrcModeEnter(_)
        | S::DrcModeExit => None,
        _ => Some(AuthorityDomain::Payload),
    }
}

/// The checks every method shares (see the module docs).
pub fn precheck(
    env: &Envelope,
    req: &ServiceRequest,
    settings: &Settings,
    snap: &Snapshot,
) -> Result<(), (u32, String)> {
    if let Some(g) = &env.gateway {
        if *g != settings.gateway_sn {
            return Err((
                codes::NOT_IN_ENUM,
                format!("gateway `{g}` is not this device ({})", settings.gateway_sn),
            ));
        }
    }
    if let Some(pi) = req.payload_index() {
        if pi != settings.payload.payload_index {
            return Err((
                codes::UNKNOWN_PAYLOAD,
                format!(
                    "payload_index `{pi}`: this aircraft has `{}`",
                    settings.payload.payload_index
                ),
            ));
        }
    }
    match authority_needed(req) {
        Some(AuthorityDomain::Flight) if !snap.holds_flight() => Err((
            codes::FLIGHT_AUTHORITY_REQUIRED,
            "flight authority is not held (flight_authority_grab first)".into(),
        )),
        Some(AuthorityDomain::Payload) if !snap.holds_payload() => Err((
            codes::PAYLOAD_AUTHORITY_REQUIRED,
            "payload authority is not held (payload_authority_grab first)".into(),
        )),
        _ => Ok(()),
    }
}

/// `|speed| ≤ max`, finite (poi_circle_speed_set).
pub fn check_speed(speed: f64, max: f64) -> Result<f64, u32> {
    if speed.is_finite() && speed.abs() <= max {
        Ok(speed)
    } else {
        Err(codes::OUT_OF_RANGE)
    }
}

/// The services side's state: the task runner's client (flight tasks, POI,
/// panorama), the DRC link, payload memory.
#[derive(Debug)]
pub struct Dispatcher {
    shared: Shared,
    drc: Arc<Mutex<Drc>>,
    tasks: TaskClient,
    /// Locked briefly by `handle` and by a camera_mode_switch once acknowledged
    /// (never across an await).
    memory: Arc<StdMutex<PayloadMemory>>,
}

impl Dispatcher {
    pub fn new(shared: Shared, drc: Drc, tasks: TaskClient) -> Self {
        Dispatcher {
            shared,
            drc: Arc::new(Mutex::new(drc)),
            tasks,
            memory: Arc::default(),
        }
    }

    pub fn task_active(&self) -> bool {
        self.tasks.task_active()
    }

    pub fn poi_active(&self) -> bool {
        self.tasks.poi_active()
    }

    pub fn pano_active(&self) -> bool {
        self.tasks.pano_active()
    }

    fn reply(&self, env: Envelope, code: u32) {
        self.shared.emit.reply(env, code);
    }

    /// A request that passed `parse_service`. Every path replies exactly once.
    pub fn handle(&mut self, env: Envelope, req: ServiceRequest) {
        let snap = self.shared.link.snapshot();
        if let Err((code, why)) = precheck(&env, &req, &self.shared.settings, &snap) {
            tracing::info!(method = %env.method, tid = %env.tid, result = code, reason = %why, "request refused");
            return self.reply(env, code);
        }
        use ServiceRequest as S;
        match req {
            S::FlightAuthorityGrab => self.grab(env, AuthorityDomain::Flight),
            S::PayloadAuthorityGrab { .. } => self.grab(env, AuthorityDomain::Payload),
            S::DrcModeEnter(enter) => {
                let (drc, emit) = (self.drc.clone(), self.shared.emit.clone());
                tokio::spawn(async move {
                    let code = drc.lock().await.enter(&enter).await;
                    emit.reply(env, code);
                });
            }
            S::DrcModeExit => {
                let (drc, emit) = (self.drc.clone(), self.shared.emit.clone());
                tokio::spawn(async move {
                    let code = drc.lock().await.exit().await;
                    emit.reply(env, code);
                });
            }
            S::TakeoffToPoint(t) => {
                let Some(heights) = self.heights(&snap) else {
                    return self.reply(env, codes::WRONG_STATE);
                };
                let target_rel = heights.rel_from_ellipsoid(t.target_height);
                let flight_alt = t.commander_flight_height.unwrap_or(target_rel);
                let target = task_point(t.target_latitude, t.target_longitude, flight_alt);
                self.tasks.takeoff(
                    env,
                    t.flight_id.clone(),
                    t.security_takeoff_height,
                    target,
                    t.max_speed as f32,
                    heights,
                );
            }
            S::FlyToPoint(f) => {
                let Some(heights) = self.heights(&snap) else {
                    return self.reply(env, codes::WRONG_STATE);
                };
                // parse_service guarantees exactly one point.
                let Some(p) = f.points.first().copied() else {
                    return self.reply(env, codes::BAD_ARRAY_SIZE);
                };
                let target = task_point(
                    p.latitude,
                    p.longitude,
                    heights.rel_from_ellipsoid(p.height),
                );
                // 0: the autopilot's own speed (WPNAV_SPEED on ArduCopter).
                let speed = (f.max_speed > 0).then_some(f.max_speed as f32);
                self.tasks
                    .fly_to(env, f.fly_to_id.clone(), target, speed, heights);
            }
            S::FlyToPointStop => self.tasks.stop(env),
            S::FlyToPointUpdate(u) => {
                let Some(heights) = self.heights(&snap) else {
                    return self.reply(env, codes::WRONG_STATE);
                };
                // parse_service guarantees exactly one point.
                let Some(p) = u.points.first().copied() else {
                    return self.reply(env, codes::BAD_ARRAY_SIZE);
                };
                let target = task_point(
                    p.latitude,
                    p.longitude,
                    heights.rel_from_ellipsoid(p.height),
                );
                self.tasks.update(env, target, u.max_speed as f32);
            }
            S::PoiModeEnter {
                latitude,
                longitude,
                height,
            } => {
                // The document: POI height is relative to the takeoff point (home).
                self.tasks
                    .poi_enter(env, task_point(latitude, longitude, height));
            }
            S::PoiModeExit => self.tasks.poi_exit(env),
            S::PoiCircleSpeedSet { circle_speed } => {
                let max = self.shared.settings.poi.max_circle_speed_mps;
                match check_speed(circle_speed, max) {
                    Ok(speed) => self.tasks.poi_speed(env, speed),
                    Err(code) => {
                        tracing::info!(circle_speed, max, "POI speed refused");
                        self.reply(env, code);
                    }
                }
            }
            other => self.payload(env, &other, &snap),
        }
    }

    fn heights(&self, snap: &Snapshot) -> Option<Heights> {
        Heights::from_snapshot(snap, self.shared.settings.flight.geoid_undulation_m)
    }

    fn grab(&self, env: Envelope, domain: AuthorityDomain) {
        let shared = self.shared.clone();
        tokio::spawn(async move {
            let cmd = match domain {
                AuthorityDomain::Flight => Command::GrabFlightAuthority,
                AuthorityDomain::Payload => Command::GrabPayloadAuthority,
            };
            let code = match shared.link.command(&cmd, 0).await {
                Ok(_) => {
                    // The AuthorityState may trail the ack: the next request is checked
                    // against it, so answer once it shows the grant; from then on the
                    // loop keeps it alive until another source takes it.
                    if wait_for_authority(&shared, domain, shared.settings.commands.ack_timeout)
                        .await
                    {
                        shared.keep.set(domain, true);
                        codes::OK
                    } else {
                        tracing::warn!(
                            ?domain,
                            "grab accepted but the arbiter's authority state never showed it"
                        );
                        codes::REFUSED_BY_ARBITER
                    }
                }
                Err(f) => {
                    tracing::info!(?domain, error = %f, "authority grab refused");
                    failure_code(&f, &cmd)
                }
            };
            shared.emit.reply(env, code);
        });
    }

    fn payload(&mut self, env: Envelope, req: &ServiceRequest, snap: &Snapshot) {
        if self.tasks.pano_active() {
            if let ServiceRequest::CameraPhotoStop { .. } = req {
                // The runner replies once stopped; if the panorama ended meanwhile,
                // an ordinary capture stop.
                let shared = self.shared.clone();
                let stop = Command::CameraCaptureStop {
                    camera: shared.settings.payload.camera,
                };
                return self.tasks.pano_stop(
                    env,
                    Box::new(move |env| {
                        tokio::spawn(async move {
                            let code = run_commands(&shared.link, &env.method, &[stop]).await;
                            shared.emit.reply(env, code);
                        });
                    }),
                );
            }
            tracing::info!(method = %env.method, "a panorama is running (camera_photo_stop ends it): refused");
            return self.reply(env, codes::WRONG_STATE);
        }
        let heights = self.heights(snap);
        let plan = {
            let mut memory = self.memory.lock().unwrap_or_else(|p| p.into_inner());
            payload::plan(
                req,
                &self.shared.settings.payload,
                snap,
                heights,
                &mut memory,
            )
        };
        match plan {
            Plan::Unsupported(why) => {
                tracing::info!(method = %env.method, reason = why, "payload method has no MAVLink equivalent here: unsupported");
                self.reply(env, codes::PAYLOAD_UNSUPPORTED);
            }
            Plan::Reject(code, why) => {
                tracing::info!(method = %env.method, result = code, reason = %why, "payload request refused");
                self.reply(env, code);
            }
            Plan::SwitchMode { command, panorama } => {
                let (shared, memory) = (self.shared.clone(), self.memory.clone());
                tokio::spawn(async move {
                    let code = run_commands(&shared.link, &env.method, &[command]).await;
                    if code == codes::OK {
                        memory.lock().unwrap_or_else(|p| p.into_inner()).panorama = panorama;
                        tracing::info!(panorama, "camera mode switched");
                    }
                    shared.emit.reply(env, code);
                });
            }
            Plan::Panorama { clear_roi } => self.tasks.pano_start(env, clear_roi),
            Plan::Commands {
                needs_flight,
                commands,
            } => {
                if needs_flight && !snap.holds_flight() {
                    tracing::info!(method = %env.method, "turning the aircraft needs flight authority");
                    return self.reply(env, codes::FLIGHT_AUTHORITY_REQUIRED);
                }
                let shared = self.shared.clone();
                tokio::spawn(async move {
                    let code = run_commands(&shared.link, &env.method, &commands).await;
                    shared.emit.reply(env, code);
                });
            }
        }
    }
}

/// Waits (at most `timeout`) until the arbiter's AuthorityState shows us holding it.
async fn wait_for_authority(shared: &Shared, domain: AuthorityDomain, timeout: Duration) -> bool {
    let holds = |s: &Snapshot| match domain {
        AuthorityDomain::Flight => s.holds_flight(),
        AuthorityDomain::Payload => s.holds_payload(),
    };
    let mut watch = shared.link.watch();
    let seen = matches!(
        tokio::time::timeout(timeout, watch.wait_for(|s| holds(s))).await,
        Ok(Ok(_))
    );
    seen
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::{AuthorityState, CommandSource};

    fn settings() -> Settings {
        skymesh_runtime::config::parse::<crate::RawConfig>("", "test").unwrap()
    }

    fn env(gateway: Option<&str>) -> Envelope {
        Envelope {
            tid: "t".into(),
            bid: "b".into(),
            timestamp: 1,
            gateway: gateway.map(String::from),
            method: "x".into(),
            data: serde_json::Value::Null,
            need_reply: None,
            seq: None,
        }
    }

    fn holding(flight: bool, payload: bool) -> Snapshot {
        let who = |b: bool| {
            if b {
                CommandSource::DjiDrc.to_wire()
            } else {
                CommandSource::ShotEngine.to_wire()
            }
        };
        Snapshot {
            authority: Some(AuthorityState {
                flight_holder: who(flight),
                payload_holder: who(payload),
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    #[test]
    fn flight_methods_need_flight_authority() {
        let s = settings();
        let stop = ServiceRequest::FlyToPointStop;
        let poi = ServiceRequest::PoiCircleSpeedSet { circle_speed: 1.0 };
        for req in [&stop, &poi] {
            assert_eq!(
                precheck(&env(None), req, &s, &holding(false, true))
                    .unwrap_err()
                    .0,
                codes::FLIGHT_AUTHORITY_REQUIRED
            );
            assert!(precheck(&env(None), req, &s, &holding(true, false)).is_ok());
        }
        // Grabbing needs nothing; neither does DRC (drone_control checks it itself).
        for req in [
            ServiceRequest::FlightAuthorityGrab,
            ServiceRequest::DrcModeExit,
        ] {
            assert!(precheck(&env(None), &req, &s, &Snapshot::default()).is_ok());
        }
    }

    #[test]
    fn payload_methods_need_their_payload_and_payload_authority() {
        let s = settings();
        let take = |pi: &str| ServiceRequest::CameraPhotoTake {
            payload_index: pi.into(),
        };
        assert_eq!(
            precheck(&env(None), &take("39-0-7"), &s, &holding(true, false))
                .unwrap_err()
                .0,
            codes::PAYLOAD_AUTHORITY_REQUIRED
        );
        assert!(precheck(&env(None), &take("39-0-7"), &s, &holding(false, true)).is_ok());
        assert_eq!(
            precheck(&env(None), &take("52-0-0"), &s, &holding(true, true))
                .unwrap_err()
                .0,
            codes::UNKNOWN_PAYLOAD,
            "checked before authority"
        );
        let grab = ServiceRequest::PayloadAuthorityGrab {
            payload_index: "1-2-3".into(),
        };
        assert_eq!(
            precheck(&env(None), &grab, &s, &Snapshot::default())
                .unwrap_err()
                .0,
            codes::UNKNOWN_PAYLOAD
        );
    }

    #[test]
    fn requests_for_another_gateway_are_refused() {
        let s = settings();
        let grab = ServiceRequest::FlightAuthorityGrab;
        assert_eq!(
            precheck(&env(Some("OTHER")), &grab, &s, &Snapshot::default())
                .unwrap_err()
                .0,
            codes::NOT_IN_ENUM
        );
        assert!(precheck(
            &env(Some("SKYMESH-DOCK-1")),
            &grab,
            &s,
            &Snapshot::default()
        )
        .is_ok());
    }

    #[test]
    fn every_method_has_its_authority() {
        use ServiceRequest as S;
        assert_eq!(
            authority_needed(&S::CameraRecordingStop {
                payload_index: "39-0-7".into()
            }),
            Some(AuthorityDomain::Payload)
        );
        assert_eq!(
            authority_needed(&S::PoiModeExit),
            Some(AuthorityDomain::Flight)
        );
        assert_eq!(authority_needed(&S::DrcModeExit), None);
    }

    #[test]
    fn poi_speed_sign_and_limit() {
        assert_eq!(check_speed(-5.0, 5.0), Ok(-5.0));
        assert_eq!(check_speed(5.01, 5.0), Err(codes::OUT_OF_RANGE));
        assert_eq!(check_speed(-5.01, 5.0), Err(codes::OUT_OF_RANGE));
        assert_eq!(check_speed(f64::NAN, 5.0), Err(codes::OUT_OF_RANGE));
    }
}
