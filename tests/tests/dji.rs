//! DJI Cloud API end to end: a test cloud (`skymesh_dji_gateway::cloud`, rumqttc)
//! talks MQTT through the real embedded broker (`skymesh-mqtt-broker`) to the real
//! `skymesh-dji-gateway`; the real `autopilot-link` arbitrates and `vehicle-sim` flies.
//! Every check is made on what the vehicle did (its `VehicleState` / `PayloadState` on
//! the bus) and on the MQTT messages the cloud received.
//!
//! One mesh runs the whole scenario, phase after phase (a mesh start and a take-off
//! cost more than most phases): each phase is an `async fn` below, and a
//! `dji e2e: <phase> took …` line on stderr marks each one passed (the first phase
//! without one is the one that failed). Order matters: the ground phases first (no
//! authority, payload, hostile input), then the flight phases, the broker outage,
//! POI, and DRC last (its emergency stop leaves the flight authority with the
//! safety source).

mod solo_common;

use std::time::{Duration, Instant};

use dji_proto::{codes, TopicKind};
use serde_json::{json, Value};
use skymesh_dji_gateway::cloud::{Cloud, DrcCloud};
use skymesh_e2e::{Mesh, MeshOptions};
use skymesh_ipc_types::{
    Command, CommandKind, CommandSource, FlightMode, PayloadState, VehicleState,
};
use solo_common::{metric, ne, offset, runtime, speed, Vehicle, STARTUP};

/// The payload the gateway is configured with (`[payload] payload_index`).
const PAYLOAD: &str = "39-0-7";
/// Waiting for an event or a vehicle state that should come (never a latency claim).
const PATIENCE: Duration = Duration::from_secs(15);
/// Flying somewhere tens of metres away at 5 m/s (vehicle-sim's limit).
const FLIGHT: Duration = Duration::from_secs(40);
/// DRC heartbeat timeout given to the gateway (`[drc] heartbeat_timeout_s`).
const HEARTBEAT_TIMEOUT_S: u64 = 5;

fn c(code: u32) -> i64 {
    i64::from(code)
}

/// The test's side of everything.
struct Ctx {
    mesh: Mesh,
    cloud: Cloud,
    drc: DrcCloud,
    v: Vehicle,
    /// Home (lat, lon), its altitude MSL and the geoid's height above the ellipsoid
    /// there as the autopilot reports it (vehicle-sim: 19.6 m); the gateway is
    /// configured with a wrong undulation (0) so only the autopilot's converts right.
    home: (f64, f64),
    home_msl: f64,
    undulation: f64,
}

impl Ctx {
    /// `data.result` of `method`'s reply; panics (naming the call) without one.
    async fn result(&self, method: &str, data: Value) -> i64 {
        let reply = self
            .cloud
            .call(method, data.clone())
            .await
            .unwrap_or_else(|e| panic!("{method} {data}: {e:#}"));
        assert_eq!(reply["method"], method, "reply to {method}: {reply}");
        reply["data"]["result"]
            .as_i64()
            .unwrap_or_else(|| panic!("{method}: reply without data.result: {reply}"))
    }

    async fn expect(&self, method: &str, data: Value, code: u32) {
        let got = self.result(method, data.clone()).await;
        assert_eq!(
            got,
            c(code),
            "{method} {data}: result {got}, expected {code}"
        );
    }

    async fn event(&self, method: &str, what: &str, pred: impl FnMut(&Value) -> bool) -> Value {
        self.event_within(method, PATIENCE, what, pred).await
    }

    async fn event_within(
        &self,
        method: &str,
        timeout: Duration,
        what: &str,
        pred: impl FnMut(&Value) -> bool,
    ) -> Value {
        match self.cloud.next_event_where(method, timeout, pred).await {
            Ok(e) => e.msg,
            Err(e) => panic!(
                "{what}: {e:#}; {method} events not taken: {:?}",
                self.cloud
                    .take_events(method)
                    .iter()
                    .map(|e| e.msg["data"].clone())
                    .collect::<Vec<_>>()
            ),
        }
    }

    /// The newest vehicle state.
    async fn state(&mut self) -> VehicleState {
        match self.v.state.latest().unwrap() {
            Some(s) => s,
            None => self.v.now().await,
        }
    }

    async fn wait_state(
        &mut self,
        timeout: Duration,
        what: &str,
        f: impl FnMut(&VehicleState) -> bool,
    ) -> VehicleState {
        self.v.wait_until(timeout, what, f).await
    }

    /// The newest gimbal state, once `f` holds for it.
    async fn wait_gimbal(
        &mut self,
        what: &str,
        mut f: impl FnMut(&PayloadState) -> bool,
    ) -> PayloadState {
        let deadline = Instant::now() + PATIENCE;
        let mut last = None;
        while Instant::now() < deadline {
            if let Some(p) = self.v.payload.recv_timeout(PATIENCE).await.unwrap() {
                if p.is_gimbal_valid() && f(&p) {
                    return p;
                }
                last = Some(p);
            }
        }
        panic!(
            "{what}: not within {PATIENCE:?}; last gimbal pitch/yaw {:?}",
            last.map(|p| (p.gimbal_pitch_deg, p.gimbal_yaw_deg))
        );
    }

    /// Ellipsoid height (what DJI sends) of `alt_rel` metres above home.
    fn height(&self, alt_rel: f64) -> f64 {
        self.home_msl + self.undulation + alt_rel
    }

    /// A gateway series (`labels` like `kind="not_json",`), 0 when absent.
    fn gw_metric(&self, name: &str, labels: &str) -> f64 {
        metric(
            &self.mesh,
            &format!("{name}{{{labels}service=\"dji-gateway\"}}"),
        )
    }
}

fn pos(s: &VehicleState) -> (f64, f64) {
    (s.lat_deg, s.lon_deg)
}

fn dist(a: (f64, f64), b: (f64, f64)) -> f64 {
    let (n, e) = ne(a, b);
    n.hypot(e)
}

/// Bearing of `p` seen from `o`, degrees clockwise from north.
fn bearing(o: (f64, f64), p: (f64, f64)) -> f64 {
    let (n, e) = ne(o, p);
    e.atan2(n).to_degrees()
}

/// `a − b` wrapped into (−180, 180].
fn wrap(d: f64) -> f64 {
    let mut d = d % 360.0;
    if d > 180.0 {
        d -= 360.0;
    } else if d <= -180.0 {
        d += 360.0;
    }
    d
}

fn point(p: (f64, f64), height: f64) -> Value {
    json!({ "latitude": p.0, "longitude": p.1, "height": height })
}

fn fly_to(id: &str, p: (f64, f64), height: f64, max_speed: i64) -> Value {
    json!({ "fly_to_id": id, "max_speed": max_speed, "points": [point(p, height)] })
}

fn takeoff(target: (f64, f64), height: f64, flight_id: &str) -> Value {
    json!({
        "target_latitude": target.0,
        "target_longitude": target.1,
        "target_height": height,
        "security_takeoff_height": 20,
        "rth_altitude": 30,
        "rc_lost_action": 0,
        "commander_mode_lost_action": 1,
        "flight_id": flight_id,
        "max_speed": 5,
    })
}

fn drc_enter(mesh: &Mesh, osd_hz: u8) -> Value {
    json!({
        "mqtt_broker": {
            "address": mesh.mqtt_addr.to_string(),
            "client_id": format!("drc-{}", mesh.gateway_sn),
            "username": "",
            "password": "",
            "expire_time": 3600,
            "enable_tls": false,
        },
        "osd_frequency": osd_hz,
        "hsi_frequency": 1,
    })
}

/// The whole DJI Cloud API surface against one mesh (see the module comment).
#[test]
fn dji_cloud_api_flies_the_vehicle_through_the_gateway() {
    let started = Instant::now();
    let mut mesh = Mesh::start(MeshOptions {
        dji: true,
        attitude_hz: 25.0,
        dji_gateway_extra: format!(
            // Wrong on purpose: the autopilot's undulation must be the one used.
            "[flight]\ngeoid_undulation_m = 0.0\n\
             [payload]\npayload_index = \"{PAYLOAD}\"\n\
             [drc]\nheartbeat_timeout_s = {HEARTBEAT_TIMEOUT_S}\n"
        ),
        ..Default::default()
    })
    .unwrap();
    mesh.expect_running(
        &[
            "vehicle-sim",
            "autopilot-link",
            "mqtt-broker",
            "dji-gateway",
        ],
        STARTUP,
    );
    let rt = runtime();
    rt.block_on(async {
        let bus = mesh.bus("e2e-dji").unwrap();
        let mut v = Vehicle::new(&bus);
        v.wait_ekf().await;
        let s = v.now().await;
        let home = pos(&s);
        let home_msl = f64::from(s.alt_msl_m - s.alt_rel_m);
        assert_eq!(s.alt_ellipsoid_valid, 1, "no alt_ellipsoid: {s:?}");
        let undulation = f64::from(s.geoid_undulation_m);
        assert!(
            undulation.abs() > 5.0,
            "a geoid undulation the heights test can see: {undulation}"
        );
        let cloud = Cloud::connect(mesh.mqtt_addr, &mesh.gateway_sn)
            .await
            .unwrap();
        let drc = DrcCloud::connect(mesh.mqtt_addr, &mesh.gateway_sn)
            .await
            .unwrap();
        let mut x = Ctx {
            mesh,
            cloud,
            drc,
            v,
            home,
            home_msl,
            undulation,
        };
        wait_gateway_online(&x).await;
        let mut phase = Instant::now();
        let mut lap = |name: &str| {
            eprintln!(
                "dji e2e: {name} took {:.1} s",
                phase.elapsed().as_secs_f64()
            );
            phase = Instant::now();
        };
        refused_without_flight_authority(&mut x).await;
        lap("refused_without_flight_authority");
        payload_methods_answer(&mut x).await;
        lap("payload_methods_answer");
        panorama_sweeps_the_gimbal(&mut x).await;
        lap("panorama_sweeps_the_gimbal");
        hostile_input_is_answered_or_counted(&mut x).await;
        lap("hostile_input_is_answered_or_counted");
        takeoff_to_point_flies_to_the_target(&mut x).await;
        lap("takeoff_to_point_flies_to_the_target");
        look_at_points_the_camera(&mut x).await;
        lap("look_at_points_the_camera");
        fly_to_point_update_and_stop(&mut x).await;
        lap("fly_to_point_update_and_stop");
        broker_outage_and_back(&mut x).await;
        lap("broker_outage_and_back");
        poi_orbits_the_point(&mut x).await;
        lap("poi_orbits_the_point");
        drc_live_flight_control(&mut x).await;
        lap("drc_live_flight_control");

        // Acknowledged need_reply events are not sent again.
        for method in [
            "takeoff_to_point_progress",
            "fly_to_point_progress",
            "camera_photo_take_progress",
        ] {
            let again: Vec<Value> = x
                .cloud
                .take_events(method)
                .into_iter()
                .map(|e| e.msg["data"].clone())
                .filter(|d| {
                    d["status"] != "wayline_progress" && d["output"]["status"] != "in_progress"
                })
                .collect();
            assert!(
                again.is_empty(),
                "{method} terminal events re-sent: {again:?}"
            );
        }
        assert_eq!(x.cloud.not_json(), 0, "the gateway sent non-JSON");
        assert_eq!(x.drc.not_json(), 0, "the DRC link sent non-JSON");
        let mesh = &mut x.mesh;
        assert_eq!(mesh.service("dji-gateway").unwrap()["restarts"], 0);
        assert_eq!(mesh.service("autopilot-link").unwrap()["restarts"], 0);
        mesh.stop(Duration::from_secs(10)).unwrap();
    });
    eprintln!(
        "dji e2e: whole scenario {:.1} s",
        started.elapsed().as_secs_f64()
    );
}

/// The gateway may still be connecting to the broker when its process is up: ask
/// something harmless (an unknown method) until it answers.
async fn wait_gateway_online(x: &Ctx) {
    let deadline = Instant::now() + STARTUP;
    loop {
        let tid = x.cloud.send("skymesh_e2e_ping", json!({})).await.unwrap();
        if let Ok(reply) = x.cloud.reply(&tid, Duration::from_secs(1)).await {
            assert_eq!(
                reply["data"]["result"],
                c(codes::UNKNOWN_METHOD),
                "unknown method: {reply}"
            );
            assert_eq!(reply["tid"], tid.as_str());
            return;
        }
        assert!(
            Instant::now() < deadline,
            "the gateway never answered on the broker"
        );
    }
}

/// Without flight authority: takeoff_to_point, fly_to_point and drone_control are
/// refused 319030 and the vehicle stays disarmed where it is. DRC mode itself can be
/// entered and left (drc_status_notify 2, then 0); heart_beat is echoed.
async fn refused_without_flight_authority(x: &mut Ctx) {
    let before = x.state().await;
    assert!(!x.v.status().await.is_armed());
    let target = offset(x.home, 20.0, 0.0);
    x.expect(
        "takeoff_to_point",
        takeoff(target, x.height(25.0), "no-authority"),
        codes::NO_FLIGHT_AUTHORITY,
    )
    .await;
    x.expect(
        "fly_to_point",
        fly_to("no-authority", target, x.height(25.0), 5),
        codes::NO_FLIGHT_AUTHORITY,
    )
    .await;

    x.expect("drc_mode_enter", drc_enter(&x.mesh, 10), codes::OK)
        .await;
    x.event("drc_status_notify", "DRC connected", |d| {
        d["drc_state"] == 2
    })
    .await;
    let r = x
        .drc
        .drone_control(0, 0.0, 3.0, 0.0, 0.0, PATIENCE)
        .await
        .unwrap();
    assert_eq!(r["result"], c(codes::NO_FLIGHT_AUTHORITY), "{r}");
    x.drc
        .send(
            "heart_beat",
            json!({ "seq": 41, "timestamp": 1_670_415_891_013_i64 }),
        )
        .await
        .unwrap();
    let hb = x
        .drc
        .next_up("heart_beat", PATIENCE)
        .await
        .expect("heart_beat echoed on drc/up");
    assert_eq!(hb.msg["data"]["seq"], 41, "{}", hb.msg);
    assert_eq!(
        hb.msg["data"]["timestamp"], 1_670_415_891_013_i64,
        "{}",
        hb.msg
    );
    x.expect("drc_mode_exit", json!({}), codes::OK).await;
    x.event("drc_status_notify", "DRC left", |d| d["drc_state"] == 0)
        .await;
    x.expect("drc_mode_exit", json!({}), codes::DRC_STATE).await;
    x.drc.take_up("osd_info_push");
    x.drc.take_up("hsi_info_push");
    x.drc.take_up("delay_info_push");

    tokio::time::sleep(Duration::from_millis(500)).await;
    let after = x.state().await;
    assert!(!x.v.status().await.is_armed(), "armed without authority");
    assert!(
        dist(pos(&before), pos(&after)) < 0.5 && after.alt_rel_m < 0.5,
        "the vehicle moved without authority: {before:?} → {after:?}"
    );
    assert!(
        x.cloud.take_events("takeoff_to_point_progress").is_empty()
            && x.cloud.take_events("fly_to_point_progress").is_empty(),
        "a refused task reported progress"
    );
}

/// payload_authority_grab first; every payload method answers: the mapped ones 0
/// with their effect on the simulated gimbal where it shows, the unmapped ones
/// PAYLOAD_UNSUPPORTED; a wrong payload_index is UNKNOWN_PAYLOAD.
async fn payload_methods_answer(x: &mut Ctx) {
    let p = |extra: Value| {
        let mut d = json!({ "payload_index": PAYLOAD });
        if let (Some(d), Some(e)) = (d.as_object_mut(), extra.as_object()) {
            d.extend(e.clone());
        }
        d
    };
    x.expect(
        "camera_photo_take",
        p(json!({})),
        codes::PAYLOAD_AUTHORITY_REQUIRED,
    )
    .await;
    x.expect(
        "payload_authority_grab",
        json!({ "payload_index": "1-0-0" }),
        codes::UNKNOWN_PAYLOAD,
    )
    .await;
    x.expect("payload_authority_grab", p(json!({})), codes::OK)
        .await;
    x.expect(
        "gimbal_reset",
        json!({ "payload_index": "1-0-0", "reset_mode": 0 }),
        codes::UNKNOWN_PAYLOAD,
    )
    .await;

    // Gimbal: recentre, aim at the upper right of the picture, pitch down keeping
    // the yaw, yaw back keeping the pitch, drag upward, look at a point east.
    x.expect("gimbal_reset", p(json!({ "reset_mode": 0 })), codes::OK)
        .await;
    x.wait_gimbal("gimbal_reset 0 → level and centred", |g| {
        g.gimbal_pitch_deg.abs() < 2.0 && g.gimbal_yaw_deg.abs() < 2.0
    })
    .await;
    x.expect(
        "camera_aim",
        p(json!({ "camera_type": "wide", "locked": false, "x": 0.75, "y": 0.25 })),
        codes::OK,
    )
    .await;
    // hfov 82°, vfov 52°: a quarter of the picture right and up is ~20° right and
    // ~13° up, whether the gateway maps it linearly or through the lens.
    let aimed = x
        .wait_gimbal("camera_aim → right and up", |g| {
            (14.0..30.0).contains(&g.gimbal_yaw_deg) && (7.0..20.0).contains(&g.gimbal_pitch_deg)
        })
        .await;
    // Straight down keeping the yaw. At −90° pitch the yaw is not observable (the
    // attitude's Euler angles are degenerate there): it shows once the drag below
    // pitches the camera up again.
    x.expect("gimbal_reset", p(json!({ "reset_mode": 3 })), codes::OK)
        .await;
    x.wait_gimbal("gimbal_reset 3 → pitch down", |g| {
        g.gimbal_pitch_deg < -87.0
    })
    .await;
    x.expect(
        "camera_screen_drag",
        p(json!({ "locked": false, "pitch_speed": 30.0, "yaw_speed": 0.0 })),
        codes::OK,
    )
    .await;
    let yaw = aimed.gimbal_yaw_deg;
    x.wait_gimbal(
        "camera_screen_drag → pitching up, the aimed yaw kept",
        |g| g.gimbal_pitch_deg > -80.0 && (g.gimbal_yaw_deg - yaw).abs() < 3.0,
    )
    .await;
    x.expect(
        "camera_screen_drag",
        p(json!({ "locked": false, "pitch_speed": 0.0, "yaw_speed": 0.0 })),
        codes::OK,
    )
    .await;
    let stopped = x.wait_gimbal("gimbal state", |_| true).await;
    tokio::time::sleep(Duration::from_millis(700)).await;
    let later = x.wait_gimbal("gimbal state", |_| true).await;
    assert!(
        (later.gimbal_pitch_deg - stopped.gimbal_pitch_deg).abs() < 5.0,
        "the gimbal kept turning after a zero drag: {} → {}",
        stopped.gimbal_pitch_deg,
        later.gimbal_pitch_deg
    );
    x.expect("gimbal_reset", p(json!({ "reset_mode": 2 })), codes::OK)
        .await;
    let pitch = later.gimbal_pitch_deg;
    x.wait_gimbal("gimbal_reset 2 → yaw centred, pitch kept", |g| {
        (g.gimbal_pitch_deg - pitch).abs() < 3.0 && g.gimbal_yaw_deg.abs() < 2.0
    })
    .await;
    // camera_look_at turns the aircraft (ArduCopter's ROI yaws it): it needs the
    // flight authority too (checked in flight, `look_at_points_the_camera`).
    let here = pos(&x.state().await);
    x.expect(
        "camera_look_at",
        p(json!({ "locked": false, "latitude": here.0, "longitude": here.1 + 0.0003, "height": x.height(0.0) + 2.0 })),
        codes::NO_FLIGHT_AUTHORITY,
    )
    .await;

    // Camera: modes, capture, recording, zoom, focus answer 0 once acknowledged.
    for (method, extra) in [
        ("camera_mode_switch", json!({ "camera_mode": 0 })),
        ("camera_photo_take", json!({})),
        ("camera_photo_stop", json!({})),
        ("camera_mode_switch", json!({ "camera_mode": 1 })),
        ("camera_recording_start", json!({})),
        ("camera_recording_stop", json!({})),
        (
            "camera_focal_length_set",
            json!({ "camera_type": "zoom", "zoom_factor": 5 }),
        ),
        (
            "camera_focus_mode_set",
            json!({ "camera_type": "zoom", "focus_mode": 1 }),
        ),
        (
            "camera_focus_mode_set",
            json!({ "camera_type": "zoom", "focus_mode": 0 }),
        ),
        (
            "camera_focus_value_set",
            json!({ "camera_type": "zoom", "focus_value": 40 }),
        ),
    ] {
        x.expect(method, p(extra), codes::OK).await;
    }
    // Checked, then refused with a reason the cloud can act on.
    x.expect(
        "camera_focal_length_set",
        p(json!({ "camera_type": "zoom", "zoom_factor": 100 })),
        codes::OUT_OF_RANGE,
    )
    .await;
    x.expect(
        "camera_focus_value_set",
        p(json!({ "camera_type": "zoom", "focus_value": 150 })),
        codes::OUT_OF_RANGE,
    )
    .await;
    // No MAVLink equivalent / no such camera: PAYLOAD_UNSUPPORTED after validation.
    for (method, extra) in [
        ("camera_mode_switch", json!({ "camera_mode": 2 })),
        (
            "camera_focal_length_set",
            json!({ "camera_type": "ir", "zoom_factor": 5 }),
        ),
        ("camera_screen_split", json!({ "enable": true })),
        (
            "photo_storage_set",
            json!({ "photo_storage_settings": ["current", "wide"] }),
        ),
        (
            "video_storage_set",
            json!({ "video_storage_settings": ["zoom"] }),
        ),
        (
            "camera_exposure_mode_set",
            json!({ "camera_type": "zoom", "exposure_mode": 2 }),
        ),
        (
            "camera_exposure_set",
            json!({ "camera_type": "zoom", "exposure_value": "20" }),
        ),
        (
            "camera_point_focus_action",
            json!({ "camera_type": "zoom", "x": 0.5, "y": 0.5 }),
        ),
        ("ir_metering_mode_set", json!({ "mode": 1 })),
        ("ir_metering_point_set", json!({ "x": 0.5, "y": 0.5 })),
        (
            "ir_metering_area_set",
            json!({ "x": 0.1, "y": 0.1, "width": 0.5, "height": 0.5 }),
        ),
    ] {
        x.expect(method, p(extra), codes::PAYLOAD_UNSUPPORTED).await;
    }
    // Invalid values are refused before anything else.
    x.expect(
        "ir_metering_area_set",
        p(json!({ "x": 0.1, "y": 0.1, "width": 1.5, "height": 0.5 })),
        codes::OUT_OF_RANGE,
    )
    .await;
}

/// `output.status` of a camera_photo_take_progress event's data.
fn pano_status(d: &Value) -> &str {
    d["output"]["status"].as_str().unwrap_or("")
}

/// The gateway's `CameraCapture` commands vehicle-sim acknowledged (MAV_RESULT
/// ACCEPTED: it counted the photo) among the acks received since the last call.
fn captures_acked(x: &mut Ctx) -> usize {
    let mut n = 0;
    while let Some(a) = x.v.acks.try_recv().unwrap() {
        if a.source == CommandSource::DjiDrc.to_wire()
            && a.kind == CommandKind::CameraCapture.to_wire()
        {
            assert!(
                a.is_accepted() && a.mav_result == 0,
                "capture refused: {a:?}"
            );
            n += 1;
        }
    }
    n
}

/// Panorama (on the ground, payload authority only): camera_mode_switch 3, then
/// camera_photo_take answers 0 with `output.status` in_progress; the gimbal turns
/// through the 8 stations 45° apart at pitch 0, starting where it points, and
/// vehicle-sim takes one photo at each; camera_photo_take_progress climbs
/// (current_step 3002, need_reply 0) to ok at 100 (3000, need_reply 1), and the
/// gimbal is back where it started. A second camera_photo_take meanwhile is refused
/// 314013. camera_photo_stop ends the next panorama (fail, result 0) and the gimbal
/// returns; camera_mode_switch 0 leaves panorama mode.
async fn panorama_sweeps_the_gimbal(x: &mut Ctx) {
    const STATIONS: usize = 8;
    let p = |extra: Value| {
        let mut d = json!({ "payload_index": PAYLOAD });
        if let (Some(d), Some(e)) = (d.as_object_mut(), extra.as_object()) {
            d.extend(e.clone());
        }
        d
    };
    captures_acked(x);
    x.cloud.take_events("camera_photo_take_progress");
    x.expect(
        "camera_mode_switch",
        p(json!({ "camera_mode": 3 })),
        codes::OK,
    )
    .await;
    let heading = x.state().await.heading_deg;
    let start = x
        .wait_gimbal("the gimbal before the panorama", |_| true)
        .await;
    let (pitch0, yaw0) = (
        f64::from(start.gimbal_pitch_deg),
        f64::from(start.gimbal_yaw_deg),
    );
    assert!(
        pitch0 < -20.0,
        "the payload phase left the camera down: {pitch0}"
    );
    let reply = x
        .cloud
        .call("camera_photo_take", p(json!({})))
        .await
        .unwrap();
    assert_eq!(reply["data"]["result"], 0, "{reply}");
    assert_eq!(reply["data"]["output"]["status"], "in_progress", "{reply}");
    x.expect("camera_photo_take", p(json!({})), codes::WRONG_STATE)
        .await;

    // Follow the gimbal, the photos and the events until the end.
    let deadline = Instant::now() + Duration::from_secs(40);
    let mut gimbal: Vec<(f64, f64)> = Vec::new();
    let mut events: Vec<Value> = Vec::new();
    let mut captures = 0;
    while !events
        .iter()
        .any(|e| pano_status(&e["data"]) != "in_progress")
    {
        assert!(
            Instant::now() < deadline,
            "the panorama never ended: {captures} photos, events {:?}",
            events.iter().map(|e| &e["data"]).collect::<Vec<_>>()
        );
        if let Some(g) =
            x.v.payload
                .recv_timeout(Duration::from_millis(200))
                .await
                .unwrap()
        {
            if g.is_gimbal_valid() {
                gimbal.push((f64::from(g.gimbal_pitch_deg), f64::from(g.gimbal_yaw_deg)));
            }
        }
        captures += captures_acked(x);
        events.extend(
            x.cloud
                .take_events("camera_photo_take_progress")
                .into_iter()
                .map(|e| e.msg),
        );
    }
    captures += captures_acked(x);
    let (progress, end) = events.split_at(events.len() - 1);
    let end = &end[0];
    let d = &end["data"];
    assert_eq!(pano_status(d), "ok", "{end}");
    assert_eq!(d["result"], 0, "{end}");
    assert_eq!(d["output"]["progress"]["percent"], 100, "{end}");
    assert_eq!(d["output"]["progress"]["current_step"], 3000, "{end}");
    assert_eq!(d["output"]["ext"]["camera_mode"], 3, "{end}");
    assert_eq!(end["need_reply"], 1, "{end}");
    let percents: Vec<i64> = progress
        .iter()
        .map(|e| {
            assert_eq!(e["need_reply"], 0, "{e}");
            assert_eq!(e["data"]["output"]["progress"]["current_step"], 3002, "{e}");
            assert_eq!(e["data"]["output"]["ext"]["camera_mode"], 3, "{e}");
            e["data"]["output"]["progress"]["percent"]
                .as_i64()
                .unwrap_or(-1)
        })
        .collect();
    eprintln!("dji e2e: panorama progress {percents:?} → 100, {captures} photos");
    assert_eq!(
        percents.len(),
        STATIONS + 1,
        "once started and after each photo: {percents:?}"
    );
    assert!(
        percents[0] == 0 && percents.windows(2).all(|w| w[0] < w[1]) && percents[STATIONS] < 100,
        "{percents:?}"
    );
    assert_eq!(captures, STATIONS, "photos vehicle-sim took");
    // Every station was visited: yaw0 + 45°·k at the horizon (within a few degrees:
    // the gimbal stops there for the photo).
    for k in 0..STATIONS {
        let want = wrap(yaw0 + 45.0 * k as f64);
        assert!(
            gimbal
                .iter()
                .any(|(p, y)| p.abs() < 4.0 && wrap(y - want).abs() < 4.0),
            "station {k} (yaw {want:.0}°) never reached; gimbal went {:.0}..{:.0}° yaw",
            gimbal.iter().map(|g| g.1).fold(f64::INFINITY, f64::min),
            gimbal.iter().map(|g| g.1).fold(f64::NEG_INFINITY, f64::max),
        );
    }
    let span = gimbal.iter().map(|g| g.1).fold(f64::NEG_INFINITY, f64::max)
        - gimbal.iter().map(|g| g.1).fold(f64::INFINITY, f64::min);
    assert!(span >= 270.0, "the gimbal covered only {span:.0}° of yaw");
    // Back where it started (the gateway waits for that before `ok`); the aircraft
    // never turned.
    let back = x
        .wait_gimbal("gimbal state after the panorama", |_| true)
        .await;
    assert!(
        (f64::from(back.gimbal_pitch_deg) - pitch0).abs() < 3.0
            && wrap(f64::from(back.gimbal_yaw_deg) - yaw0).abs() < 3.0,
        "not back at ({pitch0:.0}, {yaw0:.0}): {back:?}"
    );
    let now = x.state().await.heading_deg;
    assert!(
        wrap(f64::from(now - heading)).abs() < 2.0,
        "the aircraft turned: {heading} → {now}"
    );

    // Stopped by the cloud after the first photo.
    let reply = x
        .cloud
        .call("camera_photo_take", p(json!({})))
        .await
        .unwrap();
    assert_eq!(reply["data"]["output"]["status"], "in_progress", "{reply}");
    x.event("camera_photo_take_progress", "the first photo", |d| {
        d["output"]["progress"]["percent"].as_i64().unwrap_or(0) > 0
    })
    .await;
    x.expect("camera_photo_stop", p(json!({})), codes::OK).await;
    let stopped = x
        .event(
            "camera_photo_take_progress",
            "the stopped panorama's end",
            |d| pano_status(d) != "in_progress",
        )
        .await;
    let d = &stopped["data"];
    assert_eq!(pano_status(d), "fail", "{stopped}");
    assert_eq!(d["result"], 0, "stopped on request: {stopped}");
    assert_eq!(stopped["need_reply"], 1, "{stopped}");
    assert!(
        d["output"]["progress"]["percent"].as_i64().unwrap_or(100) < 100,
        "{stopped}"
    );
    x.wait_gimbal("the gimbal back at its start after the stop", |g| {
        (f64::from(g.gimbal_pitch_deg) - pitch0).abs() < 3.0
            && wrap(f64::from(g.gimbal_yaw_deg) - yaw0).abs() < 3.0
    })
    .await;

    // Out of panorama mode: a photo is one capture again, without progress events.
    x.expect(
        "camera_mode_switch",
        p(json!({ "camera_mode": 0 })),
        codes::OK,
    )
    .await;
    x.cloud.take_events("camera_photo_take_progress");
    captures_acked(x);
    let reply = x
        .cloud
        .call("camera_photo_take", p(json!({})))
        .await
        .unwrap();
    assert_eq!(reply["data"]["result"], 0, "{reply}");
    assert!(reply["data"].get("output").is_none(), "{reply}");
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(captures_acked(x), 1, "a single photo");
    assert!(
        x.cloud.take_events("camera_photo_take_progress").is_empty(),
        "progress events outside panorama mode"
    );
}

/// Malformed JSON, wrong types, out-of-range values (one per kind: the documented
/// code, no crash), an oversized payload, an unknown method: the gateway answers
/// what it can address, counts the rest and keeps serving.
async fn hostile_input_is_answered_or_counted(x: &mut Ctx) {
    let fly = |data: Value| ("fly_to_point", data);
    let target = offset(x.home, 10.0, 0.0);
    let h = x.height(20.0);
    for ((method, data), code) in [
        (("make_coffee", json!({})), codes::UNKNOWN_METHOD),
        (
            fly(json!({ "max_speed": 5, "points": [point(target, h)] })),
            codes::MISSING_FIELD,
        ),
        (
            fly(json!({ "fly_to_id": 7, "max_speed": 5, "points": [point(target, h)] })),
            codes::WRONG_TYPE,
        ),
        (
            fly(json!({ "fly_to_id": "a", "max_speed": "fast", "points": [point(target, h)] })),
            codes::WRONG_TYPE,
        ),
        (
            fly(
                json!({ "fly_to_id": "a", "max_speed": 5, "points": [point((91.0, target.1), h)] }),
            ),
            codes::OUT_OF_RANGE,
        ),
        (
            fly(json!({ "fly_to_id": "a", "max_speed": 16, "points": [point(target, h)] })),
            codes::OUT_OF_RANGE,
        ),
        (
            fly(json!({ "fly_to_id": "a", "max_speed": 5, "points": [] })),
            codes::BAD_ARRAY_SIZE,
        ),
        (
            fly(
                json!({ "fly_to_id": "a", "max_speed": 5, "points": [point(target, h), point(target, h)] }),
            ),
            codes::BAD_ARRAY_SIZE,
        ),
        (
            (
                "gimbal_reset",
                json!({ "payload_index": PAYLOAD, "reset_mode": 9 }),
            ),
            codes::NOT_IN_ENUM,
        ),
        (
            (
                "camera_photo_take",
                json!({ "payload_index": "not-a-payload" }),
            ),
            codes::BAD_TEXT,
        ),
        (("flight_authority_grab", json!(5)), codes::WRONG_TYPE),
    ] {
        x.expect(method, data, code).await;
    }

    // Nothing to reply to: dropped and counted by kind.
    let before = |x: &Ctx, kind: &str| {
        x.gw_metric("skymesh_dji_malformed_total", &format!("kind=\"{kind}\","))
    };
    let counts: Vec<(&str, f64)> = ["not_json", "not_object", "missing", "oversized"]
        .into_iter()
        .map(|k| (k, before(x, k)))
        .collect();
    let raw = |b: &[u8]| b.to_vec();
    x.cloud
        .publish_raw(TopicKind::Services, raw(b"{\"tid\": \"x\", \"method\": "))
        .await
        .unwrap();
    x.cloud
        .publish_raw(TopicKind::Services, raw(b"[1, 2, 3]"))
        .await
        .unwrap();
    x.cloud
        .publish_raw(
            TopicKind::Services,
            json!({ "bid": "b", "timestamp": 1, "method": "flight_authority_grab", "data": {} })
                .to_string()
                .into_bytes(),
        )
        .await
        .unwrap();
    let mut big = json!({
        "tid": "oversized", "bid": "b", "timestamp": 1, "method": "camera_photo_take",
        "data": { "payload_index": PAYLOAD, "pad": "" },
    });
    big["data"]["pad"] = Value::String("x".repeat(70 * 1024));
    x.cloud
        .publish_raw(TopicKind::Services, big.to_string().into_bytes())
        .await
        .unwrap();
    x.cloud
        .publish_raw(TopicKind::EventsReply, raw(b"\xff\xfe not json"))
        .await
        .unwrap();

    // Still serving: a valid request is answered.
    x.expect(
        "payload_authority_grab",
        json!({ "payload_index": PAYLOAD }),
        codes::OK,
    )
    .await;
    assert!(
        x.cloud
            .reply("oversized", Duration::from_millis(200))
            .await
            .is_err(),
        "an oversized request was executed"
    );
    x.mesh
        .wait_for(Duration::from_secs(10), "malformed counters", |m| {
            counts
                .iter()
                .all(|(k, n)| {
                    metric(
                        m,
                        &format!(
                            "skymesh_dji_malformed_total{{kind=\"{k}\",service=\"dji-gateway\"}}"
                        ),
                    ) > *n
                })
                .then_some(())
        })
        .unwrap_or_else(|e| {
            panic!(
                "{e:#}: {:?} → {:?}",
                counts,
                ["not_json", "not_object", "missing", "oversized"].map(|k| before(x, k))
            )
        });
    assert!(
        x.gw_metric(
            "skymesh_dji_requests_total",
            "method=\"unknown\",result=\"unknown_method\","
        ) >= 1.0
    );
}

/// Terminal `status` values of the progress events.
fn is_terminal(status: &Value) -> bool {
    status.as_str().is_some_and(|s| {
        [
            "wayline_ok",
            "wayline_failed",
            "wayline_cancel",
            "task_finish",
        ]
        .contains(&s)
    })
}

/// flight_authority_grab, then takeoff_to_point to a target 30 m away at 25 m: the
/// vehicle climbs to the safe height first, flies there, and the progress events end
/// in wayline_ok then task_finish with result 0 (each answered on events_reply).
async fn takeoff_to_point_flies_to_the_target(x: &mut Ctx) {
    x.expect("flight_authority_grab", json!({}), codes::OK)
        .await;
    let target = offset(x.home, 24.0, 18.0);
    let replies_before = x.cloud.event_replies_sent();
    x.expect(
        "takeoff_to_point",
        takeoff(target, x.height(25.0), "e2e-takeoff"),
        codes::OK,
    )
    .await;
    // Follow the vehicle and the events until a terminal one.
    let deadline = Instant::now() + FLIGHT + Duration::from_secs(15);
    let mut statuses: Vec<Value> = Vec::new();
    let mut progress_seen = 0;
    let mut max_off_low = 0.0f64;
    while !statuses.iter().any(|e| {
        e["status"] == "task_finish"
            || e["status"] == "wayline_failed"
            || e["status"] == "wayline_cancel"
    }) {
        assert!(
            Instant::now() < deadline,
            "takeoff_to_point never finished: events {statuses:?}, vehicle {:?}",
            x.state().await
        );
        let s = x.v.now().await;
        if s.alt_rel_m < 17.0 {
            max_off_low = max_off_low.max(dist(x.home, pos(&s)));
        }
        for e in x.cloud.take_events("takeoff_to_point_progress") {
            let d = e.msg["data"].clone();
            assert_eq!(d["flight_id"], "e2e-takeoff", "{d}");
            if is_terminal(&d["status"]) {
                assert_eq!(e.msg["need_reply"], 1, "terminal event: {}", e.msg);
            }
            if d["status"] == "wayline_progress" {
                progress_seen += 1;
                assert!(
                    d["remaining_distance"].as_f64().is_some_and(|r| r >= 0.0),
                    "{d}"
                );
                assert!(
                    d["planned_path_points"]
                        .as_array()
                        .is_some_and(|a| !a.is_empty()),
                    "{d}"
                );
            }
            statuses.push(d);
        }
    }
    let names: Vec<&Value> = statuses.iter().map(|d| &d["status"]).collect();
    let ok = statuses
        .iter()
        .position(|d| d["status"] == "wayline_ok")
        .unwrap_or_else(|| panic!("no wayline_ok: {names:?}"));
    let finish = statuses
        .iter()
        .position(|d| d["status"] == "task_finish")
        .unwrap_or_else(|| panic!("no task_finish: {names:?}"));
    assert!(ok < finish, "wayline_ok after task_finish: {names:?}");
    assert_eq!(statuses[ok]["result"], 0, "{:?}", statuses[ok]);
    assert_eq!(statuses[finish]["result"], 0, "{:?}", statuses[finish]);
    assert!(progress_seen >= 1, "no wayline_progress: {names:?}");
    assert!(
        max_off_low < 5.0,
        "flew {max_off_low:.1} m sideways below the 20 m safe take-off height"
    );
    let s = x
        .wait_state(PATIENCE, "hovering at the take-off target", |s| {
            speed(s) < 0.5
        })
        .await;
    assert!(
        dist(pos(&s), target) < 2.5 && (s.alt_rel_m - 25.0).abs() < 1.5,
        "not at the target: {:.1} m away at {:.1} m",
        dist(pos(&s), target),
        s.alt_rel_m
    );
    // The gateway re-sends an unanswered terminal event; ours were answered at once.
    let replies_after = x.cloud.event_replies_sent();
    assert!(
        replies_after >= replies_before + 2,
        "need_reply events not answered"
    );
}

/// In flight (flight and payload authority held): camera_look_at a point on the
/// ground 30 m east points the camera at it (the gimbal, the aircraft or both turn:
/// the camera's direction over the ground is what counts); gimbal_reset then brings
/// the gimbal back level and centred.
async fn look_at_points_the_camera(x: &mut Ctx) {
    let s = x.state().await;
    let target = offset(pos(&s), 0.0, 30.0);
    x.expect(
        "camera_look_at",
        json!({
            "payload_index": PAYLOAD, "locked": false,
            "latitude": target.0, "longitude": target.1, "height": x.height(0.0) + 2.0,
        }),
        codes::OK,
    )
    .await;
    let down = (f64::from(s.alt_rel_m) - 2.0).atan2(30.0).to_degrees();
    let deadline = Instant::now() + PATIENCE;
    loop {
        let g = x.wait_gimbal("gimbal state", |_| true).await;
        let s = x.state().await;
        let heading = f64::from(s.heading_deg) + f64::from(g.gimbal_yaw_deg);
        let want = bearing(pos(&s), target);
        if wrap(heading - want).abs() < 8.0 && (f64::from(g.gimbal_pitch_deg) + down).abs() < 8.0 {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "camera_look_at: the camera looks {heading:.0}° / {:.0}°, the point is at {want:.0}° / {:.0}°",
            g.gimbal_pitch_deg,
            -down
        );
    }
    x.expect(
        "gimbal_reset",
        json!({ "payload_index": PAYLOAD, "reset_mode": 0 }),
        codes::OK,
    )
    .await;
    x.wait_gimbal("gimbal_reset 0 after camera_look_at → centred", |g| {
        g.gimbal_pitch_deg.abs() < 2.0 && g.gimbal_yaw_deg.abs() < 2.0
    })
    .await;
}

/// fly_to_point, fly_to_point_update to a new target mid-flight → arrival there
/// (wayline_ok, result 0); another fly_to_point stopped mid-flight → wayline_cancel
/// and the vehicle stops short of it; then a fly_to_point right after the local
/// operator switched to LOITER flies (the gateway asks for GUIDED regardless of the
/// last status).
async fn fly_to_point_update_and_stop(x: &mut Ctx) {
    let s = x.state().await;
    let here = pos(&s);
    let alt = f64::from(s.alt_rel_m);
    let first = offset(here, 0.0, -25.0);
    let second = offset(here, -20.0, -5.0);
    x.expect(
        "fly_to_point",
        fly_to("e2e-a", first, x.height(alt), 5),
        codes::OK,
    )
    .await;
    x.wait_state(PATIENCE, "flying toward the first target", |s| {
        speed(s) > 1.5
    })
    .await;
    x.event("fly_to_point_progress", "progress of flyto a", |d| {
        d["fly_to_id"] == "e2e-a" && d["status"] == "wayline_progress"
    })
    .await;
    x.expect(
        "fly_to_point_update",
        json!({ "max_speed": 5, "points": [point(second, x.height(alt))] }),
        codes::OK,
    )
    .await;
    let done = x
        .event_within("fly_to_point_progress", FLIGHT, "flyto a done", |d| {
            d["fly_to_id"] == "e2e-a" && is_terminal(&d["status"])
        })
        .await;
    assert_eq!(done["data"]["status"], "wayline_ok", "{done}");
    assert_eq!(done["data"]["result"], 0, "{done}");
    assert_eq!(done["need_reply"], 1, "{done}");
    let s = x
        .wait_state(PATIENCE, "hovering at the updated target", |s| {
            speed(s) < 0.5
        })
        .await;
    assert!(
        dist(pos(&s), second) < 2.5 && dist(pos(&s), first) > 10.0,
        "not at the updated target: {:.1} m from it, {:.1} m from the first",
        dist(pos(&s), second),
        dist(pos(&s), first)
    );
    x.cloud.take_events("fly_to_point_progress");

    // Stopped mid-flight.
    let far = offset(pos(&s), 40.0, 0.0);
    x.expect(
        "fly_to_point",
        fly_to("e2e-b", far, x.height(alt), 5),
        codes::OK,
    )
    .await;
    x.wait_state(PATIENCE, "flying toward the far target", |s| speed(s) > 2.0)
        .await;
    // This time the cloud does not answer the terminal event at once: the gateway
    // sends it again (same tid) until it is answered.
    x.cloud.set_auto_reply(false);
    x.expect("fly_to_point_stop", json!({}), codes::OK).await;
    let cancel = x
        .event("fly_to_point_progress", "flyto b cancelled", |d| {
            d["fly_to_id"] == "e2e-b" && is_terminal(&d["status"])
        })
        .await;
    assert_eq!(cancel["data"]["status"], "wayline_cancel", "{cancel}");
    assert_eq!(cancel["need_reply"], 1, "{cancel}");
    let s = x
        .wait_state(PATIENCE, "stopped after fly_to_point_stop", |s| {
            speed(s) < 0.3
        })
        .await;
    let again = x
        .event(
            "fly_to_point_progress",
            "the unanswered wayline_cancel again",
            |d| d["fly_to_id"] == "e2e-b" && is_terminal(&d["status"]),
        )
        .await;
    assert_eq!(
        again["tid"], cancel["tid"],
        "a re-send keeps its tid: {again}"
    );
    x.cloud.reply_event(&again, 0).await.unwrap();
    x.cloud.set_auto_reply(true);
    assert!(
        dist(pos(&s), far) > 15.0,
        "flew on to the target after stop"
    );
    tokio::time::sleep(Duration::from_millis(800)).await;
    let later = x.state().await;
    assert!(
        dist(pos(&s), pos(&later)) < 1.0,
        "drifted {:.1} m after the stop",
        dist(pos(&s), pos(&later))
    );
    // Nothing left to stop or update.
    x.expect("fly_to_point_stop", json!({}), codes::NO_TASK)
        .await;
    x.expect(
        "fly_to_point_update",
        json!({ "max_speed": 5, "points": [point(far, x.height(alt))] }),
        codes::NO_TASK,
    )
    .await;
    x.cloud.take_events("fly_to_point_progress");

    // The local operator switches to LOITER and hands authority back; the cloud takes
    // it and flies on at once, most likely before a heartbeat has shown LOITER (the
    // status repeats the last heartbeat's GUIDED for up to a second). The gateway
    // asks for GUIDED all the same, or the vehicle would stay in LOITER.
    x.v.operator(Command::SetMode(FlightMode::Loiter)).await;
    x.v.operator(Command::ReleaseFlightAuthority).await;
    x.expect("flight_authority_grab", json!({}), codes::OK)
        .await;
    let s = x.state().await;
    let target = offset(pos(&s), 15.0, 0.0);
    x.expect(
        "fly_to_point",
        fly_to("e2e-after-loiter", target, x.height(alt), 5),
        codes::OK,
    )
    .await;
    let done = x
        .event_within(
            "fly_to_point_progress",
            FLIGHT,
            "flyto right after LOITER done",
            |d| d["fly_to_id"] == "e2e-after-loiter" && is_terminal(&d["status"]),
        )
        .await;
    assert_eq!(done["data"]["status"], "wayline_ok", "{done}");
    assert_eq!(x.v.status().await.flight_mode(), FlightMode::Guided);
    x.cloud.take_events("fly_to_point_progress");
}

/// The broker dies during a flyto and comes back (the supervisor restarts it): the
/// gateway reconnects and answers again, and the flyto completes (its wayline_ok
/// reaches the cloud).
async fn broker_outage_and_back(x: &mut Ctx) {
    let s = x.state().await;
    let alt = f64::from(s.alt_rel_m);
    let target = offset(pos(&s), 0.0, 35.0);
    let reconnects = x.gw_metric("skymesh_dji_broker_reconnects_total", "");
    x.expect(
        "fly_to_point",
        fly_to("e2e-outage", target, x.height(alt), 5),
        codes::OK,
    )
    .await;
    x.wait_state(PATIENCE, "flying toward the outage target", |s| {
        speed(s) > 1.5
    })
    .await;
    let connections = x.cloud.connections();
    let old = x.mesh.kill_service("mqtt-broker").unwrap();
    x.mesh
        .wait_restarted("mqtt-broker", old, Duration::from_secs(20))
        .unwrap();
    x.cloud
        .wait_reconnected(connections, Duration::from_secs(20))
        .await
        .unwrap();
    wait_gateway_online(x).await;
    x.expect("flight_authority_grab", json!({}), codes::OK)
        .await;
    let done = x
        .event_within(
            "fly_to_point_progress",
            FLIGHT,
            "flyto across the outage done",
            |d| d["fly_to_id"] == "e2e-outage" && is_terminal(&d["status"]),
        )
        .await;
    assert_eq!(done["data"]["status"], "wayline_ok", "{done}");
    let s = x
        .wait_state(PATIENCE, "hovering at the outage target", |s| {
            speed(s) < 0.5
        })
        .await;
    assert!(dist(pos(&s), target) < 2.5, "not at the outage target");
    assert!(
        x.gw_metric("skymesh_dji_broker_reconnects_total", "") > reconnects,
        "no reconnection counted"
    );
    x.cloud.take_events("fly_to_point_progress");
}

/// poi_mode_enter around a point 20 m away while flying: the vehicle circles it
/// (counter-clockwise for a positive speed, as DJI has it) at a constant distance;
/// poi_circle_speed_set flips the direction; poi_mode_exit stops it.
async fn poi_orbits_the_point(x: &mut Ctx) {
    let s = x.state().await;
    let alt = f64::from(s.alt_rel_m);
    let poi = offset(pos(&s), 20.0, 0.0);
    x.expect(
        "poi_mode_enter",
        json!({ "latitude": poi.0, "longitude": poi.1, "height": alt }),
        codes::OK,
    )
    .await;
    let notify = x.event("poi_status_notify", "POI entered", |_| true).await;
    let radius = notify["data"]["circle_radius"].as_f64().unwrap_or(0.0);
    assert!((17.0..23.0).contains(&radius), "{notify}");
    assert_eq!(notify["data"]["max_circle_speed"], 5.0, "{notify}");
    x.expect(
        "poi_circle_speed_set",
        json!({ "circle_speed": 5.0 }),
        codes::OK,
    )
    .await;

    // Follow the bearing from the point (unwrapped) and the distance.
    async fn circle(
        x: &mut Ctx,
        poi: (f64, f64),
        r0: f64,
        what: &str,
        mut done: impl FnMut(f64) -> bool,
    ) -> f64 {
        let deadline = Instant::now() + Duration::from_secs(30);
        let start = bearing(poi, pos(&x.state().await));
        let (mut prev, mut turned, mut worst) = (start, 0.0, 0.0f64);
        loop {
            let s = x.v.now().await;
            let b = bearing(poi, pos(&s));
            turned += wrap(b - prev);
            prev = b;
            let d = dist(poi, pos(&s));
            worst = worst.max((d - r0).abs());
            assert!(
                (d - r0).abs() < 3.0,
                "{what}: {d:.1} m from the point (radius {r0:.1}) after turning {turned:.0}°"
            );
            if done(turned) {
                eprintln!("dji e2e: {what}: turned {turned:.0}°, radius within {worst:.1} m");
                return turned;
            }
            assert!(
                Instant::now() < deadline,
                "{what}: turned only {turned:.0}° around the point"
            );
        }
    }
    let r0 = dist(poi, pos(&x.state().await));
    eprintln!("dji e2e: POI radius reported {radius:.1} m, measured {r0:.1} m");
    // Counter-clockwise seen from above: the bearing from the point decreases.
    circle(x, poi, r0, "positive circle_speed", |t| t < -90.0).await;
    x.expect(
        "poi_circle_speed_set",
        json!({ "circle_speed": -5.0 }),
        codes::OK,
    )
    .await;
    // Reversing: allow the braking, then the bearing must grow.
    let mut lowest = 0.0f64;
    circle(x, poi, r0, "negative circle_speed", |t| {
        lowest = lowest.min(t);
        t > lowest + 30.0
    })
    .await;
    x.expect(
        "poi_circle_speed_set",
        json!({ "circle_speed": 50.0 }),
        codes::OUT_OF_RANGE,
    )
    .await;
    x.cloud.take_events("poi_status_notify");
    x.expect("poi_mode_exit", json!({}), codes::OK).await;
    x.event("poi_status_notify", "POI left", |_| true).await;
    x.wait_state(PATIENCE, "stopped after poi_mode_exit", |s| speed(s) < 0.5)
        .await;
}

/// `n` drone_control at 10 Hz, 3 m/s forward, seq counting up from `seq`, sent as a
/// cloud does (without waiting for replies); then every reply must be 0 for its seq.
async fn forward_sticks(x: &mut Ctx, seq: &mut i64, n: usize) {
    let first = *seq;
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    for _ in 0..n {
        tick.tick().await;
        x.drc
            .send(
                "drone_control",
                json!({ "seq": *seq, "x": 0.0, "y": 3.0, "h": 0.0, "w": 0.0 }),
            )
            .await
            .unwrap();
        *seq += 1;
    }
    for q in first..*seq {
        let r = x.drc.next_up("drone_control", PATIENCE).await.unwrap();
        let d = &r.msg["data"];
        assert_eq!(d["result"], 0, "drone_control seq {q}: {d}");
        assert_eq!(d["output"]["seq"], q, "replies in order: {d}");
    }
}

/// DRC: drc_mode_enter naming the embedded broker; osd_info_push at about the asked
/// rate; drone_control at 10 Hz forward moves the vehicle along its heading; when the
/// stream stops it brakes and the next drone_control gets 319034; a lower seq gets
/// 319033 (seq 0 restarts); bad drc/down input is answered or counted; the emergency
/// stop hovers the vehicle; without heart_beat for heartbeat_timeout_s the gateway
/// leaves DRC (drc_status_notify 0).
async fn drc_live_flight_control(x: &mut Ctx) {
    const OSD_HZ: u8 = 10;
    x.drc.start_heartbeat(Duration::from_secs(1));
    x.cloud.take_events("drc_status_notify");
    x.expect("drc_mode_enter", drc_enter(&x.mesh, OSD_HZ), codes::OK)
        .await;
    x.event("drc_status_notify", "DRC connected", |d| {
        d["drc_state"] == 2 && d["result"] == 0
    })
    .await;

    // osd_info_push: count over a window (loose bounds: a rate, not a latency).
    let from = Instant::now();
    tokio::time::sleep(Duration::from_secs(3)).await;
    let n = x.drc.count_up("osd_info_push", from, Instant::now());
    eprintln!("dji e2e: {n} osd_info_push in 3 s at {OSD_HZ} Hz");
    let expected = 3 * usize::from(OSD_HZ);
    assert!(
        n >= expected / 2 && n <= expected * 3 / 2 + 2,
        "{n} osd_info_push in 3 s at {OSD_HZ} Hz"
    );
    let osd = x.drc.latest_up("osd_info_push").unwrap();
    let s = x.state().await;
    let d = &osd.msg["data"];
    assert!(
        (d["latitude"].as_f64().unwrap_or(0.0) - s.lat_deg).abs() < 1e-4
            && (d["longitude"].as_f64().unwrap_or(0.0) - s.lon_deg).abs() < 1e-4,
        "osd position {d} vs vehicle {s:?}"
    );
    assert!(
        x.drc.latest_up("hsi_info_push").is_some(),
        "no hsi_info_push"
    );
    x.drc.take_up("osd_info_push");

    // Forward at 3 m/s for 3 s at 10 Hz.
    let start = x.state().await;
    let (sin, cos) = start.yaw_rad.sin_cos();
    let mut seq = 1;
    forward_sticks(x, &mut seq, 30).await;
    let moving = x.state().await;
    assert!(
        speed(&moving) > 1.5,
        "drone_control did not move it: {moving:?}"
    );
    // The stream stops: the gateway brakes.
    let stopped = x
        .wait_state(PATIENCE, "braked after the stick stream stopped", |s| {
            speed(s) < 0.3
        })
        .await;
    let (n, e) = ne(pos(&start), pos(&stopped));
    let forward = f64::from(cos) * n + f64::from(sin) * e;
    let lateral = -f64::from(sin) * n + f64::from(cos) * e;
    eprintln!("dji e2e: sticks moved {forward:.1} m forward, {lateral:.1} m sideways");
    assert!(
        (5.0..14.0).contains(&forward) && lateral.abs() < 2.5,
        "3 m/s forward for 3 s moved {forward:.1} m forward, {lateral:.1} m sideways (heading {:.0}°)",
        start.yaw_rad.to_degrees()
    );
    assert!(
        (stopped.alt_rel_m - start.alt_rel_m).abs() < 1.5,
        "changed height"
    );
    // The gateway braked itself (not only the arbiter's stale-setpoint brake).
    x.mesh
        .wait_for(Duration::from_secs(10), "the DRC link's stale brake", |m| {
            (metric(
                m,
                "skymesh_dji_drc_brakes_total{reason=\"stale\",service=\"dji-gateway\"}",
            ) >= 1.0)
                .then_some(())
        })
        .unwrap();
    // The next stick command after the stale stream is refused, not flown.
    let r = x
        .drc
        .drone_control(seq, 0.0, 3.0, 0.0, 0.0, PATIENCE)
        .await
        .unwrap();
    assert_eq!(r["result"], c(codes::STICK_STALE), "{r}");
    tokio::time::sleep(Duration::from_millis(700)).await;
    let s = x.state().await;
    assert!(
        speed(&s) < 0.5,
        "the refused stick command was flown: {s:?}"
    );
    // Sequence numbers (zero sticks: hold).
    seq += 1;
    for (q, want) in [
        (seq, codes::OK),
        (seq - 3, codes::SEQ_OUT_OF_ORDER),
        (0, codes::OK),
        (1, codes::OK),
    ] {
        let r = x
            .drc
            .drone_control(q, 0.0, 0.0, 0.0, 0.0, PATIENCE)
            .await
            .unwrap();
        assert_eq!(r["result"], c(want), "drone_control seq {q}: {r}");
    }
    seq = 2;

    // Hostile drc/down input: an out-of-range stick is answered, an unknown method is
    // answered, garbage is counted; the link keeps serving.
    let malformed = x.gw_metric("skymesh_dji_drc_malformed_total", "reason=\"not_json\",");
    let r = x
        .drc
        .drone_control(seq, 100.0, 0.0, 0.0, 0.0, PATIENCE)
        .await
        .unwrap();
    assert_eq!(r["result"], c(codes::OUT_OF_RANGE), "{r}");
    seq += 1;
    x.drc.send("make_coffee", json!({})).await.unwrap();
    let r = x
        .drc
        .next_up("make_coffee", PATIENCE)
        .await
        .expect("unknown drc method answered");
    assert_eq!(
        r.msg["data"]["result"],
        c(codes::UNKNOWN_METHOD),
        "{}",
        r.msg
    );
    x.drc.publish_raw(b"{\"method\": ".to_vec()).await.unwrap();

    // The local operator takes the flight authority: the cloud hears
    // joystick_invalid_notify reason 4 (RC takeover) and sticks are refused 319030;
    // once the operator lets go, the cloud grabs it again and DRC flies on.
    x.cloud.take_events("joystick_invalid_notify");
    x.v.operator(Command::GrabFlightAuthority).await;
    let n = x
        .event(
            "joystick_invalid_notify",
            "authority taken by the operator",
            |d| d["reason"] == 4,
        )
        .await;
    assert_eq!(n["need_reply"], 1, "{n}");
    let r = x
        .drc
        .drone_control(seq, 0.0, 3.0, 0.0, 0.0, PATIENCE)
        .await
        .unwrap();
    assert_eq!(r["result"], c(codes::NO_FLIGHT_AUTHORITY), "{r}");
    seq += 1;
    x.v.operator(Command::ReleaseFlightAuthority).await;
    x.expect("flight_authority_grab", json!({}), codes::OK)
        .await;
    let r = x
        .drc
        .drone_control(seq, 0.0, 0.0, 0.0, 0.0, PATIENCE)
        .await
        .unwrap();
    assert_eq!(r["result"], 0, "sticks after the cloud grabbed again: {r}");
    seq += 1;

    // Emergency stop while moving: the vehicle brakes and hovers, in the air.
    forward_sticks(x, &mut seq, 15).await;
    x.drc.send("drone_emergency_stop", json!({})).await.unwrap();
    let r = x
        .drc
        .next_up("drone_emergency_stop", PATIENCE)
        .await
        .expect("drone_emergency_stop answered");
    assert_eq!(r.msg["data"]["result"], 0, "{}", r.msg);
    let s = x
        .wait_state(PATIENCE, "hovering after the emergency stop", |s| {
            speed(s) < 0.3
        })
        .await;
    assert!(
        x.v.status().await.is_armed() && s.alt_rel_m > 10.0,
        "the emergency stop should brake and hover, not land or disarm: {s:?}"
    );
    // Safety now holds the flight authority: sticks are refused.
    let r = x
        .drc
        .drone_control(seq, 0.0, 3.0, 0.0, 0.0, PATIENCE)
        .await
        .unwrap();
    assert_eq!(r["result"], c(codes::NO_FLIGHT_AUTHORITY), "{r}");
    x.mesh
        .wait_for(Duration::from_secs(10), "DRC malformed counter", |m| {
            (metric(
                m,
                "skymesh_dji_drc_malformed_total{reason=\"not_json\",service=\"dji-gateway\"}",
            ) > malformed)
                .then_some(())
        })
        .unwrap();

    // No heart_beat any more: DRC mode ends after the timeout.
    x.drc.stop_heartbeat();
    let silent = Instant::now();
    x.event_within(
        "drc_status_notify",
        Duration::from_secs(HEARTBEAT_TIMEOUT_S + 10),
        "DRC left after the heartbeat timeout",
        |d| d["drc_state"] == 0,
    )
    .await;
    eprintln!(
        "dji e2e: DRC left {:.1} s after the heartbeats stopped",
        silent.elapsed().as_secs_f64()
    );
    assert!(
        silent.elapsed() >= Duration::from_secs(HEARTBEAT_TIMEOUT_S - 2),
        "left DRC {:?} after the last heartbeat; the timeout is {HEARTBEAT_TIMEOUT_S} s",
        silent.elapsed()
    );
    x.drc.take_up("drone_control");
    x.drc
        .send(
            "drone_control",
            json!({ "seq": seq, "x": 0, "y": 1, "h": 0, "w": 0 }),
        )
        .await
        .unwrap();
    assert!(
        x.drc
            .next_up("drone_control", Duration::from_secs(1))
            .await
            .is_err(),
        "drone_control still answered after DRC mode ended"
    );
    x.expect("drc_mode_exit", json!({}), codes::DRC_STATE).await;
}
