//! Ready means able to serve: the whole mesh (every service of deploy/skymesh.toml,
//! on the harness's own domain and ports) is started, and the moment the supervisor
//! reports every service `running` one client per protocol sends its first request —
//! Solo (the shot on connect, a malformed and a valid geofence), DJI (a services
//! request over MQTT), DigiView (GET SYSTEM_STATUS; SET CAM_TARGETING then an
//! immediate GET), GroundControl (PING), IMC (QueryPowerChannelState) and MAVLink
//! (the vehicle's HEARTBEAT at a ground station endpoint). Each must be answered
//! correctly within 1 s, none missing: no retries, no waiting for warm-up.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use skymesh_e2e::first_requests::{report, send_all, GcsEndpoint, Targets};
use skymesh_e2e::{free_udp_port, ground, Mesh, MeshOptions};

/// The promise: a request sent when every service reports running is answered within this.
const FIRST_ANSWER: Duration = Duration::from_secs(1);
/// Start-up of thirteen debug services on two cores (not a latency claim).
const STARTUP: Duration = Duration::from_secs(90);

#[test]
fn every_protocol_answers_its_first_request_once_the_mesh_runs() {
    let gcs_port = free_udp_port();
    let gcs = GcsEndpoint::bind(gcs_port).unwrap();
    let mut mesh = Mesh::start(MeshOptions {
        solo: true,
        imc: true,
        swarm: true,
        dji: true,
        vision: true,
        link_endpoints: vec![format!("udpout:127.0.0.1:{gcs_port}")],
        ..MeshOptions::default()
    })
    .unwrap();
    let services = mesh
        .wait_all_running(STARTUP)
        .unwrap_or_else(|e| panic!("{e:#}\n{}", mesh.output()));
    let t0 = Instant::now();
    let local = |port| SocketAddr::from(([127, 0, 0, 1], port));
    let targets = Targets {
        solo: local(mesh.solo_port),
        mqtt: mesh.mqtt_addr,
        dji_sn: mesh.gateway_sn.clone(),
        digiview: local(mesh.digiview_port),
        gc: local(mesh.gc_port),
        imc: local(mesh.imc_port),
    };
    let answers = ground::runtime().block_on(send_all(&targets, gcs, t0, FIRST_ANSWER));
    let table = report(&answers);
    eprintln!(
        "first requests after {} services running:\n{table}",
        services.len()
    );
    assert_eq!(services.len(), 13, "the whole mesh: {services:?}");
    let failed: Vec<_> = answers.iter().filter(|a| a.outcome.is_err()).collect();
    assert!(
        failed.is_empty(),
        "first requests not answered correctly within {FIRST_ANSWER:?}:\n{table}\n{}",
        mesh.output()
    );
    for a in &answers {
        assert!(
            a.after <= FIRST_ANSWER,
            "{}: {:?}\n{table}",
            a.request,
            a.after
        );
    }
    mesh.stop(Duration::from_secs(10)).unwrap();
}
