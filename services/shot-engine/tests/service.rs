//! The service through real iceoryx2 shared memory, in one process: a "tool" node
//! plays solo-gateway and autopilot-link, the engine runs `run_with` on its own
//! domain. Waits are bounded by generous timeouts; nothing asserts timing.

mod common;

use skymesh_ipc_types::shot_api::{Location, ShotEvent, ShotRequest};
use skymesh_ipc_types::{
    topics, AppSession, Command, CommandKind, FlightMode, ServiceId, ShotStatus, VehicleCommand,
    VehicleState, VehicleStatus,
};
use skymesh_ipc_types::{ShotEventSample, ShotRequestSample};
use skymesh_runtime::{Bus, Publisher, Stats, Subscriber};

use common::{app_msg, settings, unique_domain, Engine, PATIENCE, VEHICLE};

struct Tool {
    from_app: Publisher<ShotRequestSample>,
    session: Publisher<AppSession>,
    state: Publisher<VehicleState>,
    status: Publisher<VehicleStatus>,
    to_app: Subscriber<ShotEventSample>,
    commands: Subscriber<VehicleCommand>,
    shot_status: Subscriber<ShotStatus>,
}

impl Tool {
    fn open(bus: &Bus) -> Tool {
        Tool {
            from_app: bus.publisher(&topics::shot_requests()).unwrap(),
            session: bus.publisher(&topics::shot_app_session()).unwrap(),
            state: bus.publisher(&topics::vehicle_state(VEHICLE)).unwrap(),
            status: bus.publisher(&topics::vehicle_status(VEHICLE)).unwrap(),
            to_app: bus.subscriber(&topics::shot_events()).unwrap(),
            commands: bus.subscriber(&topics::vehicle_command(VEHICLE)).unwrap(),
            shot_status: bus.subscriber(&topics::shot_status()).unwrap(),
        }
    }

    /// A healthy, armed vehicle in `mode`, hovering at 20 m.
    fn vehicle(&mut self, mode: FlightMode) {
        self.status
            .publish(VehicleStatus {
                vehicle_id: VEHICLE,
                mode: mode.to_wire(),
                armed: 1,
                ekf_healthy: 1,
                link_up: 1,
                battery_remaining_pct: 90,
                ..VehicleStatus::default()
            })
            .unwrap();
        self.state
            .publish(VehicleState {
                vehicle_id: VEHICLE,
                position_valid: 1,
                lat_deg: -35.363261,
                lon_deg: 149.165230,
                alt_rel_m: 20.0,
                ..VehicleState::default()
            })
            .unwrap();
    }

    /// Waits for the app message `want`, skipping others.
    /// The vehicle in LOITER and an app connecting: the engine greets it with
    /// "no shot" (GetCurrentShot(-1)).
    async fn connect_app(&mut self) {
        self.vehicle(FlightMode::Loiter);
        self.session
            .publish(AppSession {
                session: 1,
                connected: 1,
                ..AppSession::default()
            })
            .unwrap();
        self.expect_app(&ShotEvent::CurrentShot(-1)).await;
    }

    async fn expect_app(&mut self, want: &ShotEvent) {
        let wait = async {
            loop {
                let m = self.to_app.recv().await.unwrap();
                assert_eq!(m.session, 0, "to the current app");
                if m.event().as_ref() == Ok(want) {
                    return;
                }
            }
        };
        tokio::time::timeout(PATIENCE, wait)
            .await
            .unwrap_or_else(|_| panic!("no {want:?} within {PATIENCE:?}"));
    }

    /// Waits for a command of `kind`, skipping others.
    async fn expect_command(&mut self, kind: CommandKind) -> Command {
        let wait = async {
            loop {
                let c = self.commands.recv().await.unwrap();
                if c.kind == kind.to_wire() {
                    return c.command().unwrap();
                }
            }
        };
        tokio::time::timeout(PATIENCE, wait)
            .await
            .unwrap_or_else(|_| panic!("no {kind} within {PATIENCE:?}"))
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_orbit_over_the_bus_from_entry_to_exit() {
    let dir = tempfile::tempdir().unwrap();
    let domain = unique_domain();
    let tool_bus = Bus::open(&domain, "tool", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    let mut tool = Tool::open(&tool_bus);
    let engine = Engine::start(&domain, settings(dir.path())).await;

    tool.connect_app().await;

    tool.from_app
        .publish(app_msg(&ShotRequest::StartShot(1)))
        .unwrap();
    tool.expect_app(&ShotEvent::CurrentShot(1)).await;

    let roi = Location {
        lat_deg: -35.363,
        lon_deg: 149.16523,
        alt_m: 0.0,
    };
    tool.from_app
        .publish(app_msg(&ShotRequest::Location(roi)))
        .unwrap();
    tool.expect_app(&ShotEvent::Location(roi)).await;
    assert_eq!(
        tool.expect_command(CommandKind::SetMode).await,
        Command::SetMode(FlightMode::Guided)
    );
    tool.vehicle(FlightMode::Guided);
    // Setpoints flow at the loop rate.
    for _ in 0..5 {
        tool.expect_command(CommandKind::VelocityNed).await;
    }
    let st = tokio::time::timeout(PATIENCE, async {
        loop {
            let s = tool.shot_status.recv().await.unwrap();
            if s.has_authority == 1 {
                return s;
            }
        }
    })
    .await
    .expect("status");
    assert_eq!(st.shot, 1);

    tool.from_app
        .publish(app_msg(&ShotRequest::StartShot(-1)))
        .unwrap();
    tool.expect_app(&ShotEvent::CurrentShot(-1)).await;
    assert_eq!(
        tool.expect_command(CommandKind::SetMode).await,
        Command::SetMode(FlightMode::Loiter)
    );
    tool.expect_command(CommandKind::ReleaseFlightAuthority)
        .await;

    engine.stop().await;
    drop(tool);
    drop(tool_bus);
    domain.remove_leftover_files();
}

/// With the loop period set to an hour, the only setpoints are event steps: the ROI
/// that starts an orbit and a cruise-speed change each bring a setpoint at once.
/// Without the event step this waits an hour (and fails after `PATIENCE`).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn guidance_changes_send_a_setpoint_without_waiting_for_the_loop() {
    let dir = tempfile::tempdir().unwrap();
    let domain = unique_domain();
    let tool_bus = Bus::open(&domain, "tool", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    let mut tool = Tool::open(&tool_bus);
    let mut s = settings(dir.path());
    s.loop_period = std::time::Duration::from_secs(3600);
    let engine = Engine::start(&domain, s).await;

    tool.connect_app().await;
    tool.from_app
        .publish(app_msg(&ShotRequest::StartShot(1)))
        .unwrap();
    tool.expect_app(&ShotEvent::CurrentShot(1)).await;

    let roi = Location {
        lat_deg: -35.363,
        lon_deg: 149.16523,
        alt_m: 0.0,
    };
    tool.from_app
        .publish(app_msg(&ShotRequest::Location(roi)))
        .unwrap();
    tool.expect_command(CommandKind::VelocityNed).await;

    tool.vehicle(FlightMode::Guided);
    tool.from_app
        .publish(app_msg(&ShotRequest::ShotOptions { cruise_speed: 3.0 }))
        .unwrap();
    let Command::VelocityNed { vel_ned_mps, .. } =
        tool.expect_command(CommandKind::VelocityNed).await
    else {
        unreachable!("a VelocityNed");
    };
    assert!(vel_ned_mps.iter().all(|v| v.is_finite()));

    engine.stop().await;
    drop(tool);
    drop(tool_bus);
    domain.remove_leftover_files();
}
