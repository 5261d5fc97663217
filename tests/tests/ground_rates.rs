//! Telemetry rates follow the armed state, end to end: real supervisor, vehicle-sim
//! and autopilot-link with a [`FaultLink`] between the last two that logs what
//! autopilot-link asks of the autopilot (nothing is dropped).
//!
//! A disarmed vehicle gets ATTITUDE at `ground_attitude_hz` (10 Hz by default), an
//! armed one at `attitude_hz`; every arming and disarming asks again. The idle mesh
//! wakes at the ground rate, not at 50 Hz (issue 43: an idle companion computer).

use std::time::Instant;

use mavlink::dialects::ardupilotmega::{MavCmd, MavMessage, ATTITUDE_DATA};
use mavlink::MessageData;
use skymesh_e2e::fault_link::{start_faulty_mesh, Dir, FaultLink};
use skymesh_e2e::ground::{runtime, Ground, PATIENCE};
use skymesh_e2e::MeshOptions;
use skymesh_ipc_types::{AckResult, Command, CommandSource, FlightMode};

/// The ATTITUDE intervals (µs) autopilot-link asked for since `from`, in order.
fn attitude_intervals(link: &FaultLink, from: Instant) -> Vec<f32> {
    link.seen(|s| s.at >= from && s.dir == Dir::ToVehicle)
        .into_iter()
        .filter_map(|s| match s.msg {
            MavMessage::COMMAND_LONG(c)
                if c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL
                    && c.param1 == ATTITUDE_DATA::ID as f32 =>
            {
                Some(c.param2)
            }
            _ => None,
        })
        .collect()
}

/// Waits until autopilot-link has asked for ATTITUDE every `interval_us` since `from`.
async fn asked(link: &FaultLink, from: Instant, interval_us: f32, what: &str) {
    loop {
        let seen = attitude_intervals(link, from);
        if seen.contains(&interval_us) {
            return;
        }
        assert!(
            from.elapsed() < PATIENCE,
            "{what}: ATTITUDE every {interval_us} µs never asked for (asked: {seen:?})"
        );
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
}

#[test]
fn attitude_rate_follows_the_armed_state() {
    let opts = MeshOptions {
        attitude_hz: 50.0,
        ..MeshOptions::default()
    };
    let started = Instant::now();
    let (mesh, link) = start_faulty_mesh(opts, &["vehicle-sim", "autopilot-link"]).unwrap();
    runtime().block_on(async {
        let mut g = Ground::new(&mesh, "ground-rates");
        g.wait_status("EKF healthy", |s| s.ekf_healthy != 0).await;
        // Found disarmed: the ground rate (10 Hz), never the flight rate.
        asked(&link, started, 100_000.0, "on the ground").await;
        assert!(
            !attitude_intervals(&link, started).contains(&20_000.0),
            "flight rate asked for on the ground: {:?}",
            attitude_intervals(&link, started)
        );

        let ok = |a: skymesh_ipc_types::CommandAck, what: &str| {
            assert_eq!(a.result(), Some(AckResult::Accepted), "{what}: {a:?}");
        };
        ok(
            g.command(
                CommandSource::Operator,
                &Command::SetMode(FlightMode::Guided),
            )
            .await,
            "GUIDED",
        );
        let arming = Instant::now();
        ok(
            g.command(CommandSource::Operator, &Command::Arm { force: false })
                .await,
            "ARM",
        );
        g.wait_status("armed", |s| s.is_armed()).await;
        asked(&link, arming, 20_000.0, "armed").await;

        let disarming = Instant::now();
        ok(
            g.command(CommandSource::Operator, &Command::Disarm { force: false })
                .await,
            "DISARM",
        );
        g.wait_status("disarmed", |s| !s.is_armed()).await;
        asked(&link, disarming, 100_000.0, "disarmed again").await;
        println!(
            "ground_rates: ATTITUDE intervals asked (µs): {:?}",
            attitude_intervals(&link, started)
        );
    });
}
