//! The engine flies vehicle-sim through autopilot-link's arbiter, all in-process on
//! one iceoryx2 domain: a "tool" node plays the operator (takeoff) and the app
//! (solo-gateway's side of the bus). Waits are bounded; nothing asserts timing.

mod common;

use std::time::{Duration, Instant};

use skymesh_autopilot_link::config::Endpoint;
use skymesh_autopilot_link::Detached;
use skymesh_ipc_types::shot_api::{Location, ShotEvent, ShotRequest};
use skymesh_ipc_types::{
    topics, AckResult, AppSession, Button, ButtonEvent, ButtonEventKind, Command, CommandAck,
    CommandSource, FlightMode, ServiceId, ShotStatus, VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_ipc_types::{ShotEventSample, ShotRequestSample};
use skymesh_runtime::{Bus, CancellationToken, Publisher, Stats, Subscriber};

use common::{app_msg, settings, unique_domain, Engine, PATIENCE, VEHICLE};

/// One metre of latitude, degrees.
const M_LAT: f64 = 1.0 / 111_320.0;

struct Tool {
    commands: Publisher<VehicleCommand>,
    acks: Subscriber<CommandAck>,
    state: Subscriber<VehicleState>,
    status: Subscriber<VehicleStatus>,
    from_app: Publisher<ShotRequestSample>,
    session: Publisher<AppSession>,
    buttons: Publisher<ButtonEvent>,
    to_app: Subscriber<ShotEventSample>,
    shot_status: Subscriber<ShotStatus>,
    next_id: u32,
}

impl Tool {
    fn open(bus: &Bus) -> Tool {
        Tool {
            commands: bus.publisher(&topics::vehicle_command(VEHICLE)).unwrap(),
            acks: bus
                .subscriber(&topics::vehicle_command_ack(VEHICLE))
                .unwrap(),
            state: bus.subscriber(&topics::vehicle_state(VEHICLE)).unwrap(),
            status: bus.subscriber(&topics::vehicle_status(VEHICLE)).unwrap(),
            from_app: bus.publisher(&topics::shot_requests()).unwrap(),
            session: bus.publisher(&topics::shot_app_session()).unwrap(),
            buttons: bus.publisher(&topics::input_buttons()).unwrap(),
            to_app: bus.subscriber(&topics::shot_events()).unwrap(),
            shot_status: bus.subscriber(&topics::shot_status()).unwrap(),
            next_id: 1,
        }
    }

    /// An operator command and its final answer.
    async fn operator(&mut self, cmd: Command) -> CommandAck {
        let id = self.next_id;
        self.next_id += 1;
        let sample = VehicleCommand::new(VEHICLE, CommandSource::Operator, id, &cmd).unwrap();
        self.commands.publish(sample).unwrap();
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.acks.recv_timeout(left).await.unwrap() {
                Some(a)
                    if a.source == CommandSource::Operator.to_wire()
                        && a.command_id == id
                        && a.result() != Some(AckResult::InProgress) =>
                {
                    return a
                }
                Some(_) => {}
                None => panic!("no answer to {cmd:?}"),
            }
        }
    }

    async fn wait_status(&mut self, what: &str, pred: impl Fn(&VehicleStatus) -> bool) {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.status.recv_timeout(left).await.unwrap() {
                Some(s) if pred(&s) => return,
                Some(_) => {}
                None => panic!("no VehicleStatus with {what}"),
            }
        }
    }

    /// [`Self::wait_state`] while the operator's take-off climbs: as any source
    /// flying a position target must, it keeps its flight authority (a grab each
    /// second), else the arbiter brakes the climb when the authority times out.
    async fn climb_until(
        &mut self,
        what: &str,
        pred: impl Fn(&VehicleState) -> bool,
    ) -> VehicleState {
        let deadline = Instant::now() + PATIENCE;
        let mut grab = Instant::now();
        loop {
            if Instant::now() >= grab {
                grab += Duration::from_secs(1);
                let id = self.next_id;
                self.next_id += 1;
                let keep = Command::GrabFlightAuthority;
                let sample = VehicleCommand::new(VEHICLE, CommandSource::Operator, id, &keep);
                self.commands.publish(sample.unwrap()).unwrap();
            }
            let left = deadline.saturating_duration_since(Instant::now());
            let wait = left.min(Duration::from_millis(500));
            match self.state.recv_timeout(wait).await.unwrap() {
                Some(s) if pred(&s) => return s,
                Some(_) => {}
                None if left.is_zero() => panic!("no VehicleState with {what}"),
                None => {}
            }
        }
    }

    async fn wait_state(
        &mut self,
        what: &str,
        pred: impl Fn(&VehicleState) -> bool,
    ) -> VehicleState {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.state.recv_timeout(left).await.unwrap() {
                Some(s) if pred(&s) => return s,
                Some(_) => {}
                None => panic!("no VehicleState with {what}"),
            }
        }
    }

    async fn expect_app(&mut self, want: &ShotEvent) {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.to_app.recv_timeout(left).await.unwrap() {
                Some(m) if m.event().as_ref() == Ok(want) => return,
                Some(_) => {}
                None => panic!("no {want:?} for the app"),
            }
        }
    }

    fn app(&mut self, msg: ShotRequest) {
        self.from_app.publish(app_msg(&msg)).unwrap();
    }
}

fn ground_distance(s: &VehicleState, lat: f64, lon: f64) -> f64 {
    let north = (s.lat_deg - lat) / M_LAT;
    let east = (s.lon_deg - lon) / M_LAT * lat.to_radians().cos();
    north.hypot(east)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_orbit_flies_the_simulated_vehicle_around_its_roi_and_fly_hands_it_back() {
    let dir = tempfile::tempdir().unwrap();
    let domain = unique_domain();

    // vehicle-sim on a free port, autopilot-link connected to it.
    let sim_settings = skymesh_vehicle_sim::RawConfig {
        endpoint: "tcp:127.0.0.1:0".into(),
        system_id: u32::from(VEHICLE),
        ..Default::default()
    }
    .validate()
    .unwrap();
    let bound = skymesh_vehicle_sim::bind(&sim_settings).await.unwrap();
    let port = bound.local_addr().unwrap().port();
    let sim_stop = CancellationToken::new();
    let sim = tokio::spawn(skymesh_vehicle_sim::run(
        sim_settings,
        bound,
        Default::default(),
        sim_stop.clone(),
    ));
    let mut link_settings = skymesh_autopilot_link::Settings::with_connection(Endpoint::TcpOut {
        host: "127.0.0.1".into(),
        port,
    });
    // The arbiter's state file of this test, not the machine-wide default.
    link_settings.state_file = dir.path().join("autopilot-link-1.json");
    let link_bus = Bus::open(
        &domain,
        "autopilot-link",
        ServiceId::AutopilotLink,
        0,
        Stats::new(),
    )
    .unwrap();
    let link_stop = CancellationToken::new();
    let tool_bus = Bus::open(&domain, "tool", ServiceId::Tool, 0, Stats::new()).unwrap();
    let mut tool = Tool::open(&tool_bus);
    let link = tokio::spawn(skymesh_autopilot_link::run_with(
        link_settings,
        link_bus,
        Stats::new(),
        link_stop.clone(),
        Detached,
    ));
    let engine = Engine::start(&domain, settings(dir.path())).await;

    // The operator takes off to 15 m, then hands flight authority back.
    tool.wait_status("link up", |s| s.is_link_up() && s.ekf_healthy == 1)
        .await;
    for cmd in [
        Command::SetMode(FlightMode::Guided),
        Command::Arm { force: false },
        Command::Takeoff { alt_rel_m: 15.0 },
    ] {
        let ack = tool.operator(cmd).await;
        assert!(ack.is_accepted(), "{cmd:?}: {ack:?}");
    }
    let start = tool.climb_until("at 14 m", |s| s.alt_rel_m > 14.0).await;
    tool.operator(Command::ReleaseFlightAuthority).await;

    // The app connects, enters orbit and locks an ROI 20 m north.
    tool.session
        .publish(AppSession {
            session: 1,
            connected: 1,
            ..AppSession::default()
        })
        .unwrap();
    tool.expect_app(&ShotEvent::CurrentShot(-1)).await;
    tool.app(ShotRequest::StartShot(1));
    tool.expect_app(&ShotEvent::CurrentShot(1)).await;
    let roi = Location {
        lat_deg: start.lat_deg + 20.0 * M_LAT,
        lon_deg: start.lon_deg,
        alt_m: 0.0,
    };
    tool.app(ShotRequest::Location(roi));
    tool.expect_app(&ShotEvent::Location(roi)).await;
    tool.app(ShotRequest::ShotOptions { cruise_speed: 3.0 });

    // It orbits: moving, at about the radius it started at.
    let moving = tool
        .wait_state("orbiting at 2 m/s", |s| {
            s.vel_ned_mps[0].hypot(s.vel_ned_mps[1]) > 2.0
        })
        .await;
    let r = ground_distance(&moving, roi.lat_deg, roi.lon_deg);
    assert!((r - 20.0).abs() < 5.0, "orbit radius {r:.1} m");
    let st = tokio::time::timeout(PATIENCE, async {
        loop {
            let s = tool.shot_status.recv().await.unwrap();
            if s.phase == skymesh_ipc_types::ShotPhase::Running.to_wire() {
                return s;
            }
        }
    })
    .await
    .expect("running status");
    assert_eq!((st.shot, st.has_authority), (1, 1));

    // FLY: the app learns the shot ended and the pilot has LOITER.
    tool.buttons
        .publish(ButtonEvent::new(
            VEHICLE,
            Button::Fly,
            ButtonEventKind::Press,
        ))
        .unwrap();
    tool.expect_app(&ShotEvent::CurrentShot(-1)).await;
    tool.wait_status("LOITER", |s| s.flight_mode() == FlightMode::Loiter)
        .await;
    tool.wait_state("stopped", |s| {
        s.vel_ned_mps[0].hypot(s.vel_ned_mps[1]) < 0.5
    })
    .await;

    engine.stop().await;
    link_stop.cancel();
    tokio::time::timeout(Duration::from_secs(5), link)
        .await
        .expect("link stops")
        .unwrap()
        .unwrap();
    sim_stop.cancel();
    tokio::time::timeout(PATIENCE, sim)
        .await
        .expect("sim stops")
        .unwrap()
        .unwrap();
    drop(tool);
    drop(tool_bus);
    domain.remove_leftover_files();
}
