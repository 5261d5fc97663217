//! Several vehicles: one vehicle-sim + autopilot-link pair per vehicle id, every
//! vehicle topic carrying its id, commands reaching only the vehicle addressed.

use std::time::{Duration, Instant};

use skymesh_e2e::{Mesh, MeshOptions};
use skymesh_ipc_types::{
    topics, AckResult, Command, CommandAck, CommandSource, FlightMode, VehicleCommand, VehicleState,
};
use skymesh_runtime::Subscriber;

const STARTUP: Duration = Duration::from_secs(40);

/// The vehicle's first state with a position: until the autopilot's first
/// GLOBAL_POSITION_INT reaches the link, its states carry the attitude only
/// (`position_valid` 0, latitude and longitude 0).
async fn positioned(sub: &mut Subscriber<VehicleState>, id: u8) -> VehicleState {
    let deadline = Instant::now() + STARTUP;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let s = sub
            .recv_timeout(left)
            .await
            .unwrap()
            .unwrap_or_else(|| panic!("no state with a position from vehicle {id}"));
        if s.position_valid != 0 {
            return s;
        }
    }
}

#[test]
fn two_vehicles_fly_independently() {
    let opts = MeshOptions {
        vehicles: 2,
        attitude_hz: 20.0,
        ..Default::default()
    };
    let mut mesh = Mesh::start(opts).unwrap();
    for name in [
        "vehicle-sim-1",
        "vehicle-sim-2",
        "autopilot-link-1",
        "autopilot-link-2",
    ] {
        mesh.wait_running(name, STARTUP).unwrap();
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let bus = mesh.bus("e2e-fleet").unwrap();
        let mut s1 = bus
            .subscriber::<VehicleState>(&topics::vehicle_state(1))
            .unwrap();
        let mut s2 = bus
            .subscriber::<VehicleState>(&topics::vehicle_state(2))
            .unwrap();
        let mut acks2 = bus
            .subscriber::<CommandAck>(&topics::vehicle_command_ack(2))
            .unwrap();
        let mut cmds2 = bus
            .publisher::<VehicleCommand>(&topics::vehicle_command(2))
            .unwrap();

        let a = positioned(&mut s1, 1).await;
        let b = positioned(&mut s2, 2).await;
        assert_eq!((a.vehicle_id, b.vehicle_id), (1, 2));
        // Distinct simulators: vehicle 2 stands 10 m east of vehicle 1.
        let east_m = (b.lon_deg - a.lon_deg) * 111_320.0 * a.lat_deg.to_radians().cos();
        assert!(
            (east_m - 10.0).abs() < 1.0,
            "vehicle 2 is {east_m:.1} m east of vehicle 1"
        );

        let sequence = [
            Command::SetMode(FlightMode::Guided),
            Command::Arm { force: false },
            Command::Takeoff { alt_rel_m: 5.0 },
        ];
        for (i, cmd) in sequence.iter().enumerate() {
            let id = 200 + i as u32;
            cmds2
                .publish(VehicleCommand::new(2, CommandSource::Operator, id, cmd).unwrap())
                .unwrap();
            let ack = loop {
                let a = acks2
                    .recv_timeout(Duration::from_secs(10))
                    .await
                    .unwrap()
                    .expect("no ack from vehicle 2");
                if a.command_id == id {
                    break a;
                }
            };
            assert_eq!(ack.result(), Some(AckResult::Accepted), "{cmd:?} → {ack:?}");
            assert_eq!(ack.vehicle_id, 2);
        }
        let deadline = Instant::now() + Duration::from_secs(30);
        let (mut alt1, mut alt2) = (0.0f32, 0.0f32);
        while Instant::now() < deadline && alt2 < 4.5 {
            alt2 = s2
                .recv_timeout(Duration::from_secs(2))
                .await
                .unwrap()
                .expect("vehicle 2 stream stopped")
                .alt_rel_m;
            if let Some(s) = s1.latest().unwrap() {
                alt1 = s.alt_rel_m;
            }
        }
        assert!(alt2 >= 4.5, "vehicle 2 did not climb: {alt2:.2} m");
        let s = s1
            .recv_timeout(Duration::from_secs(2))
            .await
            .unwrap()
            .expect("vehicle 1 stream stopped");
        alt1 = alt1.max(s.alt_rel_m);
        assert!(
            alt1 < 0.5,
            "vehicle 1 moved although only vehicle 2 was commanded: {alt1:.2} m"
        );
    });
}
