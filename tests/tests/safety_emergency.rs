//! The emergency stop owned by its engagers, end to end (issue 42, findings 1, 2
//! and 9): real supervisor, vehicle-sim and autopilot-link, commands sent on the
//! bus under the sources' own names.
//!
//! - two engagers (dji_drc and operator): the stop stays until both released it,
//!   and a forced disarm in the air is refused `in_air`;
//! - autopilot-link SIGKILLed during a stop: after the restart the stop is in force
//!   again (from its state file), the restarted link brakes the vehicle it finds
//!   out of BRAKE, and a source that kept streaming cannot move the vehicle until
//!   the engager releases it.

use std::path::Path;
use std::time::{Duration, Instant};

use skymesh_e2e::bench::take_off;
use skymesh_e2e::ground::{runtime, Ground, PATIENCE};
use skymesh_e2e::{Mesh, MeshOptions};
use skymesh_ipc_types::{
    AckResult, Command, CommandAck, CommandSource, FlightMode, RefusalReason, VehicleState,
};
use CommandSource::{DjiDrc, Operator};

/// A mesh with vehicle-sim and autopilot-link, its state file in `dir`.
fn mesh(dir: &Path) -> Mesh {
    Mesh::start(MeshOptions {
        autopilot_link_extra: format!(
            "state_file = {:?}",
            dir.join("autopilot-link.json").display().to_string()
        ),
        ..MeshOptions::default()
    })
    .unwrap()
}

fn speed(s: &VehicleState) -> f32 {
    let [n, e, _] = s.vel_ned_mps;
    n.hypot(e)
}

fn outcome(a: &CommandAck) -> (Option<AckResult>, Option<RefusalReason>) {
    (a.result(), a.reason())
}

const ACCEPTED: (Option<AckResult>, Option<RefusalReason>) =
    (Some(AckResult::Accepted), Some(RefusalReason::None));

fn refused(r: RefusalReason) -> (Option<AckResult>, Option<RefusalReason>) {
    (Some(AckResult::Refused), Some(r))
}

#[test]
fn two_engagers_hold_the_stop_until_both_release_and_a_forced_disarm_in_the_air_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = mesh(dir.path());
    runtime().block_on(async {
        take_off(&mesh, 8.0).await.unwrap();
        let mut g = Ground::new(&mesh, "safety-emergency");

        // Finding 9: a forced disarm in flight is a motor kill, refused.
        let a = g.command(Operator, &Command::Disarm { force: true }).await;
        assert_eq!(outcome(&a), refused(RefusalReason::InAir), "{a:?}");
        // Still armed: the next status (once a second at least) says so.
        let status = g.status.recv_timeout(PATIENCE).await.unwrap();
        assert!(status.expect("status").is_armed());

        // Finding 1: the DJI pilot and the operator each stop the vehicle.
        let a = g.command(DjiDrc, &Command::EmergencyStop).await;
        assert_eq!(outcome(&a), ACCEPTED, "dji_drc stop: {a:?}");
        let a = g.command(Operator, &Command::EmergencyStop).await;
        assert_eq!(outcome(&a), ACCEPTED, "operator stop: {a:?}");
        g.wait_authority("both engaged", |s| {
            s.emergency == 1 && s.emergency_by(DjiDrc) && s.emergency_by(Operator)
        })
        .await;
        // The operator ends its own stop; the DJI pilot's still holds everyone.
        let a = g.command(Operator, &Command::ReleaseEmergency).await;
        assert_eq!(outcome(&a), ACCEPTED, "{a:?}");
        assert_eq!(
            a.detail.as_str(),
            "operator released; still held by dji_drc"
        );
        let st = g
            .wait_authority("operator released", |s| !s.emergency_by(Operator))
            .await;
        assert_eq!(
            (st.emergency, st.flight()),
            (1, Some(CommandSource::Safety))
        );
        let guided = Command::SetMode(FlightMode::Guided);
        let a = g.command(Operator, &guided).await;
        assert_eq!(outcome(&a), refused(RefusalReason::Emergency), "{a:?}");
        // Releasing authority does not end it either; shot_engine may not clear it.
        let a = g
            .command(CommandSource::Safety, &Command::ReleaseFlightAuthority)
            .await;
        assert_eq!(a.result(), Some(AckResult::Accepted), "{a:?}");
        let a = g
            .command(CommandSource::ShotEngine, &Command::ClearEmergency)
            .await;
        assert_eq!(outcome(&a), refused(RefusalReason::Denied), "{a:?}");
        // The next AuthorityState (one a second at least) still has the stop.
        let st = g.authority.recv_timeout(PATIENCE).await.unwrap();
        assert_eq!(st.expect("authority").emergency, 1);
        let a = g.command(Operator, &guided).await;
        assert_eq!(outcome(&a), refused(RefusalReason::Emergency), "{a:?}");
        // The DJI pilot releases: the stop ends and the operator commands again.
        let a = g.command(DjiDrc, &Command::ReleaseEmergency).await;
        assert_eq!(
            (outcome(&a), a.detail.as_str()),
            (ACCEPTED, "emergency stop ended")
        );
        g.wait_authority("stop ended", |s| {
            s.emergency == 0 && s.emergency_sources == 0
        })
        .await;
        let a = g.command(Operator, &guided).await;
        assert_eq!(outcome(&a), ACCEPTED, "{a:?}");
        println!("safety_emergency: two engagers, stop held until both released");
    });
}

#[test]
fn a_stop_survives_a_sigkill_of_autopilot_link_and_a_streaming_source_cannot_move_the_vehicle() {
    let dir = tempfile::tempdir().unwrap();
    let mut mesh = mesh(dir.path());
    let rt = runtime();
    let mut g = rt.block_on(async {
        take_off(&mesh, 8.0).await.unwrap();
        let mut g = Ground::new(&mesh, "safety-emergency");
        // The DJI pilot flies north at 3 m/s (10 Hz stream), the operator stops it.
        let push = Command::VelocityNed {
            vel_ned_mps: [3.0, 0.0, 0.0],
            yaw_rate_dps: None,
        };
        let started = Instant::now();
        loop {
            g.send(DjiDrc, &push);
            tokio::time::sleep(Duration::from_millis(100)).await;
            if speed(&g.state.latest().unwrap().expect("state")) > 2.5 {
                break;
            }
            assert!(started.elapsed() < PATIENCE, "never reached 2.5 m/s");
        }
        let a = g.command(Operator, &Command::EmergencyStop).await;
        assert_eq!(outcome(&a), ACCEPTED, "stop: {a:?}");
        g.wait_authority("operator's stop", |s| s.emergency_by(Operator))
            .await;
        // The vehicle leaves BRAKE (safety may command in a stop; a pilot's mode
        // switch would do the same): after the restart only the restored latch
        // puts it back.
        let a = g
            .command(CommandSource::Safety, &Command::SetMode(FlightMode::Loiter))
            .await;
        assert_eq!(outcome(&a), ACCEPTED, "LOITER: {a:?}");
        g.wait_status("LOITER", |s| s.flight_mode() == FlightMode::Loiter)
            .await;
        g
    });
    let saved = std::fs::read_to_string(dir.path().join("autopilot-link.json")).unwrap();
    assert!(saved.contains("\"operator\""), "state file: {saved}");

    let old = mesh.kill_service("autopilot-link").unwrap();
    let killed = Instant::now();
    let new = mesh
        .wait_restarted("autopilot-link", old, Duration::from_secs(30))
        .unwrap();
    assert_ne!(old, new);

    rt.block_on(async {
        let push = Command::VelocityNed {
            vel_ned_mps: [3.0, 0.0, 0.0],
            yaw_rate_dps: None,
        };
        // The DJI pilot kept streaming through the restart: every setpoint is
        // refused (link_down until the restarted link is up, then emergency).
        g.early.clear();
        let mut first_emergency = None;
        let mut ids = Vec::new();
        let deadline = Instant::now() + PATIENCE;
        while first_emergency.is_none() {
            ids.push(g.send(DjiDrc, &push));
            tokio::time::sleep(Duration::from_millis(100)).await;
            while let Some(a) = g.acks.try_recv().unwrap() {
                if a.source == DjiDrc.to_wire() && ids.contains(&a.command_id) {
                    assert_ne!(a.result(), Some(AckResult::Accepted), "{a:?}");
                    if a.reason() == Some(RefusalReason::Emergency) {
                        first_emergency = Some(Instant::now());
                    }
                }
            }
            assert!(
                Instant::now() < deadline,
                "no emergency refusal after the restart"
            );
        }
        // The restarted link found a latch and an armed vehicle in LOITER: it
        // brakes it, with no stop command sent since.
        g.wait_status("BRAKE after the restart", |s| {
            s.is_link_up() && s.flight_mode() == FlightMode::Brake
        })
        .await;
        let st = g
            .wait_authority("restored stop", |s| s.emergency == 1)
            .await;
        assert!(st.emergency_by(Operator), "{st:?}");
        assert_eq!(st.flight(), Some(CommandSource::Safety));
        let a = g
            .command(DjiDrc, &Command::SetMode(FlightMode::Guided))
            .await;
        assert_eq!(outcome(&a), refused(RefusalReason::Emergency), "{a:?}");
        // Three more seconds of streaming: refused, and the vehicle stays put.
        let from = g.state.latest().unwrap().expect("state");
        let (mut refused_n, end) = (0, Instant::now() + Duration::from_secs(3));
        while Instant::now() < end {
            let id = g.send(DjiDrc, &push);
            let a = g.ack(id).await;
            assert_eq!(outcome(&a), refused(RefusalReason::Emergency), "{a:?}");
            refused_n += 1;
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        let to = g.state.latest().unwrap().expect("state");
        let moved_m = {
            let dn = (to.lat_deg - from.lat_deg) * 111_320.0;
            let de = (to.lon_deg - from.lon_deg) * 111_320.0 * from.lat_deg.to_radians().cos();
            dn.hypot(de)
        };
        assert!(
            speed(&to) < 0.5 && moved_m < 1.0,
            "moved {moved_m:.2} m: {to:?}"
        );
        // The engager releases: the stream is obeyed again.
        let a = g.command(Operator, &Command::ReleaseEmergency).await;
        assert_eq!(
            (outcome(&a), a.detail.as_str()),
            (ACCEPTED, "emergency stop ended")
        );
        let a = g.command(DjiDrc, &push).await;
        assert_ne!(a.reason(), Some(RefusalReason::Emergency), "{a:?}");
        println!(
            "safety_emergency: restart {:.1} s after the kill, latched from the state file; \
             {refused_n} setpoints refused in 3 s, moved {moved_m:.2} m",
            first_emergency
                .unwrap()
                .duration_since(killed)
                .as_secs_f64()
        );
    });
}
