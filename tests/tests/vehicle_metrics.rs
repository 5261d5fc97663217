//! The supervisor's `skymesh_vehicle_*` gauges (services/supervisor/src/vehicles.rs)
//! through the real processes: vehicle-sim, autopilot-link and the supervisor's
//! `/metrics`, while the vehicle takes off.

use std::time::{Duration, Instant};

use skymesh_e2e::ground::{runtime, Ground};
use skymesh_e2e::{find_metric, Mesh, MeshOptions};
use skymesh_ipc_types::FlightMode;

const STARTUP: Duration = Duration::from_secs(30);
/// Generous: a take-off to 10 m takes about 10 s on an idle machine.
const FLIGHT: Duration = Duration::from_secs(90);

const FAMILIES: [&str; 9] = [
    "skymesh_vehicle_altitude_meters",
    "skymesh_vehicle_ground_speed_meters_per_second",
    "skymesh_vehicle_battery_remaining_ratio",
    "skymesh_vehicle_battery_voltage_volts",
    "skymesh_vehicle_armed",
    "skymesh_vehicle_mode",
    "skymesh_vehicle_link_up",
    "skymesh_vehicle_telemetry_age_seconds",
    "skymesh_vehicle_status_age_seconds",
];

fn gauge(metrics: &str, name: &str) -> Option<f64> {
    find_metric(metrics, &format!("{name}{{vehicle=\"1\"}}"))
}

fn mode(metrics: &str, mode: FlightMode) -> Option<f64> {
    find_metric(
        metrics,
        &format!(
            "skymesh_vehicle_mode{{mode=\"{}\",vehicle=\"1\"}}",
            mode.as_str()
        ),
    )
}

/// Scrapes `/metrics` until `done` accepts it, calling `between` between scrapes;
/// fails after `within` with the last scrape.
async fn scrape_until(
    mesh: &Mesh,
    within: Duration,
    what: &str,
    mut between: impl FnMut(),
    done: impl Fn(&str) -> bool,
) -> String {
    let deadline = Instant::now() + within;
    loop {
        let metrics = mesh.http_get("/metrics").unwrap();
        if done(&metrics) {
            return metrics;
        }
        assert!(
            Instant::now() < deadline,
            "{what}: not seen within {within:?}; last /metrics:\n{metrics}\n{}",
            mesh.output()
        );
        between();
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
}

#[test]
fn the_supervisor_exports_the_vehicle_gauges_and_they_follow_a_takeoff() {
    let mut mesh = Mesh::start(MeshOptions::default()).unwrap();
    // The first scrape has every family for the configured vehicle (1, the
    // default), whatever the vehicle has said so far.
    let first = mesh.http_get("/metrics").unwrap();
    for name in FAMILIES {
        assert!(
            first.contains(&format!("# TYPE {name} gauge")),
            "{name} missing from the first scrape:\n{first}"
        );
    }
    assert!(mode(&first, FlightMode::Guided).is_some(), "{first}");
    assert!(
        gauge(&first, "skymesh_vehicle_link_up").is_some(),
        "{first}"
    );

    mesh.wait_running("autopilot-link", STARTUP).unwrap();
    let rt = runtime();
    rt.block_on(async {
        // On the ground with the link up: altitude about 0, disarmed.
        let ground = scrape_until(
            &mesh,
            STARTUP,
            "link up with a position",
            || {},
            |m| {
                gauge(m, "skymesh_vehicle_link_up") == Some(1.0)
                    && gauge(m, "skymesh_vehicle_altitude_meters").is_some_and(f64::is_finite)
            },
        )
        .await;
        let alt0 = gauge(&ground, "skymesh_vehicle_altitude_meters").unwrap();
        assert!(alt0.abs() < 1.0, "on the ground: {alt0} m\n{ground}");
        assert_eq!(
            gauge(&ground, "skymesh_vehicle_armed"),
            Some(0.0),
            "{ground}"
        );
        let age = gauge(&ground, "skymesh_vehicle_telemetry_age_seconds").unwrap();
        assert!(age.is_finite() && age >= 0.0, "{ground}");
        let speed = gauge(&ground, "skymesh_vehicle_ground_speed_meters_per_second").unwrap();
        assert!(speed.is_finite() && speed >= 0.0, "{ground}");

        let mut operator = Ground::new(&mesh, "e2e-gauges");
        operator.take_off(10.0).await;

        // The operator keeps its flight authority while the take-off flies (a grab
        // about every second), as a source flying a position target must.
        let flying = scrape_until(
            &mesh,
            FLIGHT,
            "altitude above 5 m, armed, guided",
            || operator.keep_authority(),
            |m| {
                gauge(m, "skymesh_vehicle_altitude_meters").is_some_and(|a| a > 5.0)
                    && gauge(m, "skymesh_vehicle_armed") == Some(1.0)
                    && mode(m, FlightMode::Guided) == Some(1.0)
            },
        )
        .await;
        println!(
            "altitude on the ground {alt0:.2} m, in flight {:.2} m",
            gauge(&flying, "skymesh_vehicle_altitude_meters").unwrap_or(f64::NAN)
        );
        assert_eq!(mode(&flying, FlightMode::Stabilize), Some(0.0), "{flying}");
        assert_eq!(
            gauge(&flying, "skymesh_vehicle_link_up"),
            Some(1.0),
            "{flying}"
        );
        let battery = gauge(&flying, "skymesh_vehicle_battery_remaining_ratio").unwrap();
        assert!(
            battery.is_nan() || (0.0..=1.0).contains(&battery),
            "battery {battery}\n{flying}"
        );
    });
}
