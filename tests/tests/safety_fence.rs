//! Fences that stack, end to end (issue 42, findings 6 and 7): real supervisor,
//! vehicle-sim and autopilot-link, fences and commands sent on the bus under the
//! sources' own names.
//!
//! - the swarm queue (GroundControl) sets a 60 m box, the shot engine (Solo) a 30 m
//!   fence; the shot engine may not clear the box, clears its own, and a velocity
//!   stream pushing north is still held by the box, the margin inside;
//! - the box replaced by a long, narrow one: a stream at 10 degrees to its east
//!   wall slides along it and stops at least the margin from it.

use std::time::{Duration, Instant};

use skymesh_autopilot_link::arbiter::geofence::LocalFrame;
use skymesh_e2e::bench::take_off;
use skymesh_e2e::ground::runtime;
use skymesh_e2e::{Mesh, MeshOptions, HOME};
use skymesh_ipc_types::{
    topics, ArbiterEvent, ArbiterEventKind, Command, CommandSource, FenceKind, GeofenceSet,
    VehicleCommand, VehicleState, NO_HOLDER,
};
use skymesh_runtime::{Publisher, Subscriber};
use CommandSource::{Operator, ShotEngine, SwarmQueue};

/// autopilot-link's `[arbiter] fence_margin_m` (its default).
const MARGIN: f64 = 2.0;
/// Waiting for something that should happen (never a latency claim).
const PATIENCE: Duration = Duration::from_secs(30);
/// Setpoint stream period.
const PERIOD: Duration = Duration::from_millis(50);

/// The arbiter's own projection, so the test measures what it enforces.
fn frame() -> LocalFrame {
    LocalFrame::new(HOME[0], HOME[1])
}

fn ne(s: &VehicleState) -> [f64; 2] {
    let p = frame().to_local(s.lat_deg, s.lon_deg);
    [p.x, p.y]
}

/// Latitude, longitude of (north, east) m from home.
fn ll(n: f64, e: f64) -> [f64; 2] {
    let unit = frame().to_local(HOME[0] + 1e-3, HOME[1] + 1e-3);
    [HOME[0] + n / unit.x * 1e-3, HOME[1] + e / unit.y * 1e-3]
}

/// `source`'s keep-in rectangle: north `n0..n1`, east `e0..e1` m.
fn keep_in(
    source: CommandSource,
    request_id: u32,
    (n0, n1): (f64, f64),
    (e0, e1): (f64, f64),
) -> GeofenceSet {
    let mut set = GeofenceSet {
        vehicle_id: 1,
        enabled: 1,
        source: source.to_wire(),
        request_id,
        ceiling_m: 60.0,
        floor_m: -10.0,
        ..Default::default()
    };
    assert!(set.push_polygon(
        FenceKind::KeepIn,
        &[ll(n0, e0), ll(n1, e0), ll(n1, e1), ll(n0, e1)]
    ));
    set
}

fn clear(source: CommandSource, target: Option<CommandSource>, request_id: u32) -> GeofenceSet {
    GeofenceSet {
        vehicle_id: 1,
        enabled: 0,
        source: source.to_wire(),
        target_source: target.map_or(NO_HOLDER, CommandSource::to_wire),
        request_id,
        ..Default::default()
    }
}

struct Ground {
    cmds: Publisher<VehicleCommand>,
    fence: Publisher<GeofenceSet>,
    events: Subscriber<ArbiterEvent>,
    state: Subscriber<VehicleState>,
    next_id: u32,
}

impl Ground {
    /// The arbiter's decision on the fence sample `set` (matched by request id).
    async fn fence(&mut self, set: &GeofenceSet) -> (ArbiterEventKind, String) {
        self.fence.publish(*set).unwrap();
        let deadline = Instant::now() + PATIENCE;
        loop {
            let e = self
                .events
                .recv_timeout(PATIENCE)
                .await
                .unwrap()
                .expect("an arbiter event");
            let kind = e.event_kind();
            if e.request_id == set.request_id
                && matches!(
                    kind,
                    Some(ArbiterEventKind::GeofenceUpdated | ArbiterEventKind::GeofenceInvalid)
                )
            {
                return (kind.unwrap(), e.detail.as_str().to_string());
            }
            assert!(
                Instant::now() < deadline,
                "no decision on {}",
                set.request_id
            );
        }
    }

    /// Streams `vel` (NED) as the operator for `secs`, then stops the stream and
    /// waits for the vehicle to come to rest. Returns the largest `f(position)`
    /// seen on the way.
    async fn stream(&mut self, vel: [f32; 3], secs: f64, f: impl Fn([f64; 2]) -> f64) -> f64 {
        let mut worst = f64::NEG_INFINITY;
        let end = Instant::now() + Duration::from_secs_f64(secs);
        let mut tick = tokio::time::interval(PERIOD);
        while Instant::now() < end {
            tick.tick().await;
            self.next_id += 1;
            let cmd = Command::VelocityNed {
                vel_ned_mps: vel,
                yaw_rate_dps: None,
            };
            self.cmds
                .publish(VehicleCommand::new(1, Operator, self.next_id, &cmd).unwrap())
                .unwrap();
            while let Ok(Some(s)) = self.state.recv_timeout(Duration::ZERO).await {
                worst = worst.max(f(ne(&s)));
            }
        }
        // The stream stopped: the arbiter brakes it; wait for rest.
        let deadline = Instant::now() + PATIENCE;
        let mut still_since = None;
        loop {
            let s = self
                .state
                .recv_timeout(PATIENCE)
                .await
                .unwrap()
                .expect("vehicle state");
            worst = worst.max(f(ne(&s)));
            let speed = s.vel_ned_mps[0].hypot(s.vel_ned_mps[1]);
            if speed < 0.05 {
                let since = *still_since.get_or_insert_with(Instant::now);
                if since.elapsed() > Duration::from_secs(1) {
                    return worst;
                }
            } else {
                still_since = None;
            }
            assert!(Instant::now() < deadline, "never came to rest");
        }
    }
}

#[test]
fn fences_of_two_sources_hold_together_and_the_box_survives_the_other() {
    let mesh = Mesh::start(MeshOptions::default()).unwrap();
    let rt = runtime();
    rt.block_on(async {
        let bus = mesh.bus("safety-fence").unwrap();
        let mut g = Ground {
            cmds: bus.publisher(&topics::vehicle_command(1)).unwrap(),
            fence: bus.publisher(&topics::vehicle_geofence(1)).unwrap(),
            events: bus.subscriber(&topics::vehicle_arbiter_events(1)).unwrap(),
            state: bus.subscriber(&topics::vehicle_state(1)).unwrap(),
            next_id: 100,
        };
        take_off(&mesh, 10.0).await.unwrap();

        // GroundControl's box and the Solo app's smaller fence, both in force.
        let (kind, detail) = g
            .fence(&keep_in(SwarmQueue, 11, (-30.0, 30.0), (-30.0, 30.0)))
            .await;
        assert_eq!(kind, ArbiterEventKind::GeofenceUpdated, "{detail}");
        let (kind, detail) = g
            .fence(&keep_in(ShotEngine, 12, (-15.0, 15.0), (-15.0, 15.0)))
            .await;
        assert_eq!(
            (kind, detail.as_str()),
            (
                ArbiterEventKind::GeofenceUpdated,
                "shot_engine: 1 polygons, -10..60 m; 2 fences"
            )
        );
        // The shot engine may not clear the box.
        let (kind, detail) = g.fence(&clear(ShotEngine, Some(SwarmQueue), 13)).await;
        assert_eq!(
            (kind, detail.as_str()),
            (
                ArbiterEventKind::GeofenceInvalid,
                "shot_engine may not clear swarm_queue's fence"
            )
        );
        // North at 5 m/s: the Solo fence holds first.
        let north = g.stream([5.0, 0.0, 0.0], 10.0, |p| p[0]).await;
        eprintln!("north at 5 m/s: at most {north:.2} m north");
        assert!(
            north <= 15.0 - MARGIN + 0.05 && north > 10.0,
            "Solo fence: {north:.2} m"
        );
        // The app disconnects: its fence is cleared; the box still holds.
        let (kind, detail) = g.fence(&clear(ShotEngine, None, 14)).await;
        assert_eq!(
            (kind, detail.as_str()),
            (
                ArbiterEventKind::GeofenceUpdated,
                "shot_engine cleared its fence; 1 left"
            )
        );
        let north = g.stream([5.0, 0.0, 0.0], 10.0, |p| p[0]).await;
        eprintln!("north at 5 m/s: at most {north:.2} m north");
        assert!(
            north <= 30.0 - MARGIN + 0.05 && north > 24.0,
            "box: {north:.2} m"
        );

        // A long narrow box; a stream at 10 degrees to its east wall (12 m east),
        // southward: the wall 10 m beyond the margin, 57 m ahead along the ray.
        let (kind, detail) = g
            .fence(&keep_in(SwarmQueue, 15, (-120.0, 60.0), (-12.0, 12.0)))
            .await;
        assert_eq!(kind, ArbiterEventKind::GeofenceUpdated, "{detail}");
        let a = 10f64.to_radians();
        let vel = [(-5.0 * a.cos()) as f32, (5.0 * a.sin()) as f32, 0.0];
        let east = g.stream(vel, 20.0, |p| p[1]).await;
        eprintln!("10 degrees to the wall 12 m east: at most {east:.2} m east");
        assert!(east <= 12.0 - MARGIN + 0.05, "10 degrees: {east:.2} m east");
        assert!(east > 6.0, "it did approach the wall: {east:.2} m east");
    });
}
