//! `Command::SetHome` against vehicle-sim, in-process: real TCP on 127.0.0.1, real
//! iceoryx2 shared memory in a domain of its own per test.
//!
//! Timeouts are generous (the machine may be slow and busy); nothing asserts on
//! timing.

mod common;

use std::time::Duration;

use common::sim::Sim;
use common::{assert_accepted, Mesh};
use skymesh_autopilot_link::arbiter::geofence::LocalFrame;
use skymesh_ipc_types::{AckResult, Command, FlightMode, RefusalReason};

/// vehicle-sim's home.
const HOME: (f64, f64) = (-35.363261, 149.165230);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn set_home_moves_home_and_rtl_flies_to_the_new_one() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start(sim.port).await;
    mesh.wait_link_up().await;
    mesh.take_off(10.0).await;
    let before = mesh.wait_status("home", |s| s.home_valid == 1).await;
    let frame = LocalFrame::new(HOME.0, HOME.1);
    let unit = frame.to_local(HOME.0 + 1e-3, HOME.1 + 1e-3);
    // 40 m east of the old home (within the arbiter's `max_home_move_m`, 50 m by
    // default), at the same altitude above sea level.
    let east = 40.0 / unit.y * 1e-3;
    let (lat, lon, alt_msl) = (
        before.home_lat_deg,
        before.home_lon_deg + east,
        before.home_alt_msl_m,
    );

    let ack = mesh
        .command(Command::SetHome {
            lat_deg: lat,
            lon_deg: lon,
            alt_msl_m: alt_msl,
        })
        .await;
    assert_accepted(&ack, "set home");
    assert_eq!(ack.mav_result, 0, "MAV_RESULT_ACCEPTED");
    // The sim announces the new home (HOME_POSITION) and VehicleStatus carries it.
    let status = mesh
        .wait_status("the new home", |s| {
            s.home_valid == 1 && (s.home_lon_deg - lon).abs() < 1e-6
        })
        .await;
    assert!((status.home_lat_deg - lat).abs() < 1e-6);
    assert!((status.home_alt_msl_m - alt_msl).abs() < 0.01);
    let moved = frame.to_local(status.home_lat_deg, status.home_lon_deg);
    assert!(
        (moved.y - 40.0).abs() < 0.5 && moved.x.abs() < 0.5,
        "{moved:?}"
    );
    assert!(
        mesh.metric(
            "skymesh_autopilot_commands_total",
            "kind=set_home,result=accepted"
        ) >= 1.0
    );

    // A home the arbiter bounds: lat = lon = 0 (ArduPilot's "here"; the plan
    // refuses it `unsupported`, see commands.rs) is thousands of km away, and a
    // home 5 m above the current one's altitude would make RTL fly elsewhere.
    // Both refused before anything is sent.
    let sent = mesh.metric(
        "skymesh_autopilot_commands_total",
        "kind=set_home,result=accepted",
    );
    for (what, lat, lon, alt) in [
        ("0/0", 0.0, 0.0, 100.0),
        ("5 m up", lat, lon, alt_msl + 5.0),
    ] {
        let ack = mesh
            .command(Command::SetHome {
                lat_deg: lat,
                lon_deg: lon,
                alt_msl_m: alt,
            })
            .await;
        assert_eq!(ack.result(), Some(AckResult::Refused), "{what}");
        assert_eq!(
            ack.reason(),
            Some(RefusalReason::Denied),
            "{what}: {:?}",
            ack.detail
        );
    }
    assert_eq!(
        mesh.metric(
            "skymesh_autopilot_commands_total",
            "kind=set_home,result=accepted"
        ),
        sent
    );

    // RTL now returns to the new home, not to where the vehicle took off.
    assert_accepted(&mesh.command(Command::ReturnToLaunch).await, "RTL");
    mesh.wait_status("RTL", |s| s.flight_mode() == FlightMode::Rtl)
        .await;
    let new_home = frame.to_local(lat, lon);
    let over_home = mesh
        .wait_state("over the new home", Duration::from_secs(120), |s| {
            (frame.to_local(s.lat_deg, s.lon_deg) - new_home).norm() < 3.0
        })
        .await;
    let p = frame.to_local(over_home.lat_deg, over_home.lon_deg);
    assert!(p.norm() > 35.0, "away from the take-off point: {p:?}");
    assert!(over_home.alt_rel_m > 5.0, "still in the air, returning");
    mesh.stop().await;
    sim.stop().await;
}
