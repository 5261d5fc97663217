//! The arbiter's topics seen from a test tool, commands from any source, and a
//! take-off helper.

use std::time::{Duration, Instant};

use skymesh_ipc_types::{
    topics, AckResult, ArbiterEvent, ArbiterEventKind, AuthorityState, Command, CommandAck,
    CommandSource, FlightMode, GeofenceSet, ServiceId, VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::{Bus, Publisher, Stats, Subscriber};

use super::{assert_accepted, Mesh, PATIENCE, VEHICLE};

/// Subscribers to the arbiter's output and a geofence publisher, on a node of
/// their own. Drop before [`Mesh::stop`].
pub struct ArbiterPorts {
    pub authority: Subscriber<AuthorityState>,
    pub events: Subscriber<ArbiterEvent>,
    pub geofence: Publisher<GeofenceSet>,
    _bus: Bus,
}

impl ArbiterPorts {
    pub fn open(mesh: &Mesh) -> ArbiterPorts {
        let bus = Bus::open(
            &mesh.domain,
            "test-arbiter",
            ServiceId::Tool,
            1,
            Stats::new(),
        )
        .expect("arbiter test bus");
        ArbiterPorts {
            authority: bus
                .subscriber(&topics::vehicle_authority(VEHICLE))
                .expect("authority subscriber"),
            events: bus
                .subscriber(&topics::vehicle_arbiter_events(VEHICLE))
                .expect("events subscriber"),
            geofence: bus
                .publisher(&topics::vehicle_geofence(VEHICLE))
                .expect("geofence publisher"),
            _bus: bus,
        }
    }

    /// Waits for an `AuthorityState` matching `pred` (published on change and at 1 Hz).
    pub async fn wait_authority(
        &mut self,
        what: &str,
        pred: impl Fn(&AuthorityState) -> bool,
    ) -> AuthorityState {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.authority.recv_timeout(left).await.expect("authority") {
                Some(s) if pred(&s) => return s,
                Some(_) => {}
                None => panic!("no AuthorityState with {what} within {PATIENCE:?}"),
            }
        }
    }

    /// Waits for the next `ArbiterEvent` of `kind` (others are skipped).
    pub async fn wait_event(&mut self, kind: ArbiterEventKind) -> ArbiterEvent {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.events.recv_timeout(left).await.expect("event") {
                Some(e) if e.event_kind() == Some(kind) => return e,
                Some(_) => {}
                None => panic!("no {kind} event within {PATIENCE:?}"),
            }
        }
    }
}

impl Mesh {
    /// Publishes `cmd` from `source` (max_age_ms 0 = the arbiter's default).
    pub fn send_as(&mut self, source: CommandSource, cmd: Command, max_age_ms: u32) -> u32 {
        let mut sample = VehicleCommand::new(VEHICLE, source, 0, &cmd).expect("valid command");
        sample.max_age_ms = max_age_ms;
        self.send(sample)
    }

    /// Publishes `cmd` from `source` and returns its final answer.
    pub async fn command_as(&mut self, source: CommandSource, cmd: Command) -> CommandAck {
        let id = self.send_as(source, cmd, 0);
        self.answer_to(id).await
    }

    /// GUIDED, armed, climbed to about `alt_m` (as the operator).
    pub async fn take_off(&mut self, alt_m: f32) -> VehicleState {
        self.wait_status("a healthy EKF and home", |s| {
            s.ekf_healthy == 1 && s.home_valid == 1
        })
        .await;
        assert_accepted(
            &self.command(Command::SetMode(FlightMode::Guided)).await,
            "GUIDED",
        );
        self.wait_status("GUIDED", |s| s.flight_mode() == FlightMode::Guided)
            .await;
        assert_accepted(&self.command(Command::Arm { force: false }).await, "arm");
        self.wait_status("armed", VehicleStatus::is_armed).await;
        assert_accepted(
            &self.command(Command::Takeoff { alt_rel_m: alt_m }).await,
            "takeoff",
        );
        // A source flying to a position target keeps flight authority, as a real
        // client must: one silent for the authority timeout (5 s) loses it, and the
        // arbiter brakes its orphaned target (a 10 m climb at 2.5 m/s takes longer).
        let deadline = Instant::now() + Duration::from_secs(90);
        let mut next_grab = Instant::now() + Duration::from_secs(1);
        loop {
            let now = Instant::now();
            assert!(now < deadline, "no take-off altitude {alt_m} m within 90 s");
            if now >= next_grab {
                self.send_as(CommandSource::Operator, Command::GrabFlightAuthority, 0);
                next_grab = now + Duration::from_secs(1);
            }
            let wait = next_grab.min(deadline).saturating_duration_since(now);
            if let Some(s) = self.state.recv_timeout(wait).await.expect("state") {
                if s.alt_rel_m >= alt_m - 0.3 {
                    return s;
                }
            }
        }
    }
}

/// Horizontal speed, m/s.
pub fn ground_speed(s: &VehicleState) -> f32 {
    s.vel_ned_mps[0].hypot(s.vel_ned_mps[1])
}

pub fn assert_result(ack: &CommandAck, result: AckResult, what: &str) {
    assert_eq!(
        ack.result(),
        Some(result),
        "{what}: {:?} {:?}",
        ack.reason(),
        ack.detail
    );
}
