//! The core against the fake fleet, with explicit time (30 Hz ticks, no sleeping).

use std::path::Path;

use skymesh_ipc_types::{
    drone_flags, swarm_flags, CommandKind, CommandSource, DroneState, HardwareOp, LcdOp,
    SwarmCommand, SwarmCommandKind as K, SwarmReply, SwarmResult, SwarmState, VehicleCommand,
    ALL_DRONES,
};
use skymesh_runtime::Stats;

use super::*;
use crate::anim::{AnimLibrary, Animation};
use crate::config::RawConfig;
use crate::fake::FakeFleet;
use crate::metrics::Metrics;

const TICK_NS: u64 = 33_333_333;
const T0: u64 = 1_000_000_000_000;

fn settings(n: usize, extra: &str) -> Settings {
    let text = format!(
        "site_origin = {{ lat_deg = -35.363261, lon_deg = 149.165230, alt_msl_m = 584.0 }}\n\
         drones = {{ first_id = 1, count = {n}, first_vehicle_id = 11 }}\n\
         hardware_drone = 1\n{extra}\n"
    );
    let raw: RawConfig = toml::from_str(&text).unwrap();
    raw.validate_in(Path::new("/nonexistent")).unwrap()
}

/// A 2 s animation: east 4 m in 1 s, back in 1 s, at 3 m; red → green → blue.
fn anim() -> Animation {
    Animation::parse(
        "time_s,x,y,z,yaw_deg,r,g,b\n0,0,0,3,0,1,0,0\n1,4,0,3,0,0,1,0\n2,0,0,3,0,0,0,1\n",
    )
    .unwrap()
}

struct H {
    swarm: Swarm,
    fleet: FakeFleet,
    now: u64,
    stats: Stats,
    replies: Vec<SwarmReply>,
    sent: Vec<VehicleCommand>,
    geofences: Vec<Box<GeofenceSet>>,
    hardware: Vec<HardwareRequest>,
    next_request: u32,
}

impl H {
    fn new(n: usize) -> H {
        H::with(n, "")
    }

    fn with(n: usize, extra: &str) -> H {
        let cfg = settings(n, extra);
        let stats = Stats::new();
        let ids: Vec<u16> = cfg.drones.iter().map(|d| d.id).collect();
        let mut swarm = Swarm::new(
            cfg,
            AnimLibrary::new("/nonexistent"),
            Metrics::new(&stats, &ids),
            T0,
        );
        for id in &ids {
            swarm.anims_mut().insert(*id, anim());
        }
        let fleet = FakeFleet::for_swarm(&swarm, 3.0);
        let mut h = H {
            swarm,
            fleet,
            now: T0,
            stats,
            replies: Vec::new(),
            sent: Vec::new(),
            geofences: Vec::new(),
            hardware: Vec::new(),
            next_request: 1,
        };
        h.step();
        h
    }

    fn pump(&mut self) {
        for _ in 0..16 {
            let out = self.swarm.take_outputs();
            if out.is_empty() {
                break;
            }
            self.fleet.deliver(&mut self.swarm, &out.commands, self.now);
            self.fleet
                .deliver_geofences(&mut self.swarm, &out.geofences, self.now);
            self.sent.extend(out.commands);
            self.geofences.extend(out.geofences);
            self.hardware.extend(out.hardware);
        }
        while let Some(r) = self.swarm.pop_reply() {
            self.replies.push(r);
        }
    }

    fn step(&mut self) {
        self.now += TICK_NS;
        self.fleet
            .step(&mut self.swarm, TICK_NS as f64 / 1e9, self.now);
        self.swarm.tick(self.now);
        self.pump();
    }

    fn run(&mut self, secs: f64) {
        for _ in 0..(secs * 30.0).round() as usize {
            self.step();
        }
    }

    /// Steps until `pred` holds; false after `secs`.
    fn run_until(&mut self, secs: f64, pred: impl Fn(&H) -> bool) -> bool {
        for _ in 0..(secs * 30.0) as usize {
            if pred(self) {
                return true;
            }
            self.step();
        }
        pred(self)
    }

    fn send(&mut self, drone: u16, kind: K, set: impl FnOnce(&mut SwarmCommand)) -> u32 {
        let mut c = SwarmCommand {
            request_id: self.next_request,
            client: 7,
            drone,
            kind: kind.to_wire(),
            ..SwarmCommand::default()
        };
        if !kind.is_ext() {
            c.flags |= swarm_flags::PRIVILEGED;
        }
        set(&mut c);
        self.next_request += 1;
        self.swarm.handle_command(&c, self.now);
        self.pump();
        c.request_id
    }

    fn waypoint(&mut self, drone: u16, p: [f32; 3]) -> u32 {
        self.send(drone, K::ExtWaypoint, |c| c.f[..3].copy_from_slice(&p))
    }

    fn replies_to(&self, request: u32) -> Vec<&SwarmReply> {
        self.replies
            .iter()
            .filter(|r| r.request_id == request)
            .collect()
    }

    fn reply(&self, request: u32, drone: u16) -> Option<(SwarmResult, String)> {
        self.replies
            .iter()
            .find(|r| r.request_id == request && r.drone == drone)
            .map(|r| (r.result().unwrap(), r.reason.as_str().to_string()))
    }

    fn answered(&self, request: u32, drone: u16) -> bool {
        self.reply(request, drone).is_some()
    }

    fn state(&self) -> SwarmState {
        let mut s = SwarmState::default();
        self.swarm.fill_state(self.now, &mut s);
        s
    }

    fn take_off(&mut self, drone: u16) {
        let r = self.send(drone, K::ExtGoExternal, |_| {});
        let drones: Vec<u16> = if drone == ALL_DRONES {
            (0..self.swarm.len())
                .map(|i| self.swarm.drone(i).id)
                .collect()
        } else {
            vec![drone]
        };
        assert!(self.run_until(20.0, |h| drones.iter().all(|d| h.answered(r, *d))));
        for d in drones {
            assert_eq!(
                self.reply(r, d).unwrap().0,
                SwarmResult::Success,
                "drone {d}"
            );
        }
    }

    fn sent_kinds(&self, vehicle: u8) -> Vec<CommandKind> {
        self.sent
            .iter()
            .filter(|c| c.vehicle_id == vehicle)
            .map(|c| CommandKind::try_from(c.kind).unwrap())
            .collect()
    }

    fn counter(&self, kind: &str, outcome: &str) -> u64 {
        self.stats
            .counter(
                "skymesh_swarm_commands_total",
                &[("kind", kind), ("outcome", outcome)],
            )
            .get()
    }
}

fn close(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
    dist(a, b) <= tol
}

#[test]
fn every_drone_takes_off_through_guided_arm_takeoff() {
    let mut h = H::new(5);
    let s = h.state();
    assert_eq!(s.count, 5);
    assert!(s
        .drones()
        .iter()
        .all(|d| d.drone_state == DroneState::OnGround.to_wire()));
    assert!(s.drones().iter().all(|d| d.flags & drone_flags::IDLE != 0));
    let r = h.send(ALL_DRONES, K::ExtGoExternal, |_| {});
    assert_eq!(
        h.state().drones[0].drone_state,
        DroneState::TakeoffWait.to_wire(),
        "taking off, not armed yet"
    );
    h.run(0.3);
    assert_eq!(
        h.state().drones[0].drone_state,
        DroneState::Takeoff.to_wire()
    );
    assert!(h.run_until(10.0, |h| (1..=5).all(|d| h.answered(r, d))));
    for d in 1..=5u16 {
        assert_eq!(h.reply(r, d).unwrap().0, SwarmResult::Success);
    }
    assert_eq!(
        h.sent_kinds(11),
        [CommandKind::SetMode, CommandKind::Arm, CommandKind::Takeoff]
    );
    for v in &h.fleet.vehicles {
        assert!(v.alt_rel() >= 1.99, "{}", v.alt_rel());
    }
    let s = h.state();
    assert!(s
        .drones()
        .iter()
        .all(|d| d.drone_state == DroneState::FollowTarget.to_wire()));
    assert_eq!(h.counter("ext_go_external", "success"), 5);
    // Again while flying: finishes at once.
    let again = h.send(3, K::ExtGoExternal, |_| {});
    assert_eq!(
        h.reply(again, 3),
        Some((SwarmResult::Success, "already flying".into()))
    );
}

#[test]
fn waypoints_are_queued_and_flown_in_order() {
    let mut h = H::new(2);
    h.take_off(1);
    let points = [[5.0, 0.0, 3.0], [5.0, 5.0, 4.0], [0.0, 5.0, 3.0]];
    let ids: Vec<u32> = points.iter().map(|p| h.waypoint(1, *p)).collect();
    assert_eq!(h.state().drones[0].queue_depth, 2);
    assert_eq!(h.state().drones[0].current, K::ExtWaypoint.to_wire());
    assert_eq!(h.state().drones[0].target, points[0]);
    assert!(h.run_until(30.0, |h| h.answered(ids[2], 1)));
    let order: Vec<u32> = h
        .replies
        .iter()
        .filter(|r| ids.contains(&r.request_id))
        .map(|r| r.request_id)
        .collect();
    assert_eq!(order, ids, "finished in order");
    for id in &ids {
        assert_eq!(h.reply(*id, 1).unwrap().0, SwarmResult::Success);
    }
    let s = h.state();
    assert!(
        close(s.drones[0].tracking, points[2], 0.5),
        "{:?}",
        s.drones[0].tracking
    );
    assert!(s.drones[0].flags & drone_flags::IDLE != 0);
    // The waypoints flew at the default speed, facing the commanded yaw (0 = east).
    let goto = h
        .sent
        .iter()
        .find(|c| c.kind == CommandKind::GoTo.to_wire())
        .unwrap()
        .command()
        .unwrap();
    match goto {
        Command::GoTo {
            yaw_deg, speed_mps, ..
        } => {
            assert_eq!(yaw_deg, Some(90.0));
            assert_eq!(speed_mps, Some(2.0));
        }
        other => panic!("{other:?}"),
    }
    assert!(
        h.fleet.vehicles[1].alt_rel() < 0.1,
        "the other drone stayed down"
    );
}

/// Someone (the pilot, a ground station) switches the vehicle to LOITER, and a
/// waypoint comes before a heartbeat has shown it: the last status still says
/// GUIDED. The waypoint asks for GUIDED anyway and flies; trusting the status, its
/// position target went to a vehicle in LOITER, which ignores it, and it timed out.
#[test]
fn a_waypoint_asks_for_guided_even_when_the_last_status_says_guided() {
    let mut h = H::new(1);
    h.take_off(1);
    assert_eq!(
        h.swarm.drone(0).status.unwrap().flight_mode(),
        FlightMode::Guided
    );
    h.fleet.vehicles[0].mode = FlightMode::Loiter;
    let r = h.waypoint(1, [3.0, 3.0, 3.0]);
    assert!(h.run_until(30.0, |h| h.answered(r, 1)));
    assert_eq!(h.reply(r, 1).unwrap().0, SwarmResult::Success);
    assert_eq!(h.fleet.vehicles[0].mode, FlightMode::Guided);
    let kinds: Vec<_> = h
        .sent_kinds(11)
        .into_iter()
        .filter(|k| *k != CommandKind::GrabFlightAuthority)
        .collect();
    assert_eq!(
        kinds[3..],
        [CommandKind::SetMode, CommandKind::GoTo],
        "after the takeoff's three (keep-alives aside)"
    );

    // A dragged manual target (each replacing the last before it is reached) asks
    // once, not once per target.
    let before = h.sent_kinds(11).len();
    for i in 0..5 {
        let p = [10.0 + i as f32, 3.0, 3.0];
        h.send(1, K::SetManualTarget, |c| c.f[..3].copy_from_slice(&p));
        h.step();
    }
    let kinds = &h.sent_kinds(11)[before..];
    assert_eq!(kinds[0], CommandKind::SetMode, "{kinds:?}");
    assert!(
        kinds[1..].iter().all(|k| *k == CommandKind::GoTo),
        "{kinds:?}"
    );
    assert_eq!(kinds.len(), 6, "{kinds:?}");
}

#[test]
fn a_waypoint_on_the_ground_is_refused_and_yaw_is_converted() {
    let mut h = H::new(1);
    let r = h.waypoint(1, [1.0, 1.0, 2.0]);
    assert_eq!(
        h.reply(r, 1),
        Some((SwarmResult::Refused, "not flying: take off first".into()))
    );
    h.take_off(1);
    let r = h.send(1, K::ExtWaypoint, |c| {
        c.f[..4].copy_from_slice(&[0.0, 0.0, 3.0, 4.0]);
        c.int1 = 18_000; // facing west
    });
    assert!(h.run_until(10.0, |h| h.answered(r, 1)));
    assert_eq!(h.fleet.vehicles[0].heading, 270.0);
    let s = h.state();
    assert!((s.drones[0].tracking_yaw_deg.abs() - 180.0).abs() < 0.01);
}

#[test]
fn waypoint_follow_replaces_the_running_one_and_never_finishes() {
    let mut h = H::new(1);
    h.take_off(1);
    let follow =
        |h: &mut H, p: [f32; 3]| h.send(1, K::ExtWaypointFollow, |c| c.f[..3].copy_from_slice(&p));
    let a = follow(&mut h, [20.0, 0.0, 3.0]);
    h.run(0.5);
    let b = follow(&mut h, [0.0, 6.0, 3.0]);
    assert_eq!(
        h.reply(a, 1),
        Some((SwarmResult::Success, "replaced by a newer follow".into()))
    );
    assert_eq!(h.state().drones[0].queue_depth, 0, "no new queue entry");
    assert_eq!(h.state().drones[0].target, [0.0, 6.0, 3.0]);
    h.run(8.0);
    let s = h.state();
    assert!(
        close(s.drones[0].tracking, [0.0, 6.0, 3.0], 0.3),
        "{:?}",
        s.drones[0].tracking
    );
    assert!(!h.answered(b, 1), "a follow never finishes by itself");
    // A waypoint queued behind it waits; a follow replaces a queued follow too.
    let w = h.waypoint(1, [1.0, 1.0, 3.0]);
    let c = follow(&mut h, [1.0, 6.0, 3.0]);
    assert_eq!(h.reply(b, 1).unwrap().0, SwarmResult::Success);
    assert_eq!(h.state().drones[0].queue_depth, 1);
    h.run(2.0);
    assert!(!h.answered(w, 1) && !h.answered(c, 1));
    let halt = h.send(1, K::ExtHalt, |_| {});
    assert_eq!(h.reply(halt, 1).unwrap().0, SwarmResult::Success);
    assert_eq!(h.reply(c, 1), Some((SwarmResult::Refused, "halted".into())));
    assert_eq!(h.reply(w, 1), Some((SwarmResult::Refused, "halted".into())));
}

#[test]
fn follow_targets_are_streamed_at_the_setpoint_rate() {
    let mut h = H::new(1);
    h.take_off(1);
    let before = h.sent.len();
    for i in 0..30 {
        h.send(1, K::ExtWaypointFollow, |c| {
            c.f[..3].copy_from_slice(&[i as f32 * 0.1, 0.0, 3.0])
        });
        h.step();
    }
    let gotos = h.sent[before..]
        .iter()
        .filter(|c| c.kind == CommandKind::GoTo.to_wire())
        .count();
    assert!(
        (9..=12).contains(&gotos),
        "{gotos} position targets in 1 s at 10 Hz"
    );
    // Speed is sent only when it changes.
    let with_speed = h.sent[before..]
        .iter()
        .filter(|c| c.kind == CommandKind::GoTo.to_wire() && c.flags & 0x04 != 0)
        .count();
    assert_eq!(
        with_speed, 1,
        "the first target sets the speed, the others keep it"
    );
}

#[test]
fn halt_empties_the_queue_and_brakes() {
    let mut h = H::new(1);
    h.take_off(1);
    let ids: Vec<u32> = (0..3)
        .map(|i| h.waypoint(1, [10.0 + i as f32, 0.0, 3.0]))
        .collect();
    h.run(1.0);
    let halt = h.send(1, K::ExtHalt, |_| {});
    assert_eq!(h.reply(halt, 1).unwrap().0, SwarmResult::Success);
    for id in ids {
        assert_eq!(
            h.reply(id, 1),
            Some((SwarmResult::Refused, "halted".into()))
        );
    }
    assert_eq!(h.sent_kinds(11).last(), Some(&CommandKind::Brake));
    let s = h.state();
    assert_eq!(s.drones[0].queue_depth, 0);
    assert_eq!(s.drones[0].current, 0);
    assert!(s.drones[0].flags & drone_flags::IDLE != 0);
    let x = h.fleet.vehicles[0].pos[0];
    h.run(1.0);
    assert!((h.fleet.vehicles[0].pos[0] - x).abs() < 0.01, "stopped");
    assert_eq!(h.counter("ext_waypoint", "refused"), 3);
    assert_eq!(h.counter("ext_halt", "success"), 1);
}

#[test]
fn halt_and_save_then_push_saved_resumes_the_command() {
    let mut h = H::new(1);
    h.take_off(1);
    let w = h.waypoint(1, [10.0, 0.0, 3.0]);
    let q = h.waypoint(1, [0.0, 0.0, 3.0]);
    h.run(1.0);
    let save = h.send(1, K::ExtHaltAndSaveCurCmd, |_| {});
    assert_eq!(h.reply(save, 1).unwrap().0, SwarmResult::Success);
    assert!(!h.answered(w, 1), "the saved command is not over");
    assert_eq!(h.reply(q, 1), Some((SwarmResult::Refused, "halted".into())));
    assert!(h.state().drones[0].flags & drone_flags::HAS_SAVED != 0);
    let push = h.send(1, K::ExtPushSavedCmd, |_| {});
    assert_eq!(h.reply(push, 1).unwrap().0, SwarmResult::Success);
    assert!(h.state().drones[0].flags & drone_flags::HAS_SAVED == 0);
    assert!(h.run_until(20.0, |h| h.answered(w, 1)));
    assert_eq!(h.reply(w, 1).unwrap().0, SwarmResult::Success);
    let again = h.send(1, K::ExtPushSavedCmd, |_| {});
    assert_eq!(
        h.reply(again, 1),
        Some((SwarmResult::Refused, "no saved command".into()))
    );
}

#[test]
fn pause_holds_for_its_seconds() {
    let mut h = H::new(1);
    let p = h.send(1, K::ExtPause, |c| c.f[0] = 2.0);
    let after = h.send(1, K::ExtPause, |c| c.f[0] = 0.0);
    h.run(1.9);
    assert!(!h.answered(p, 1));
    assert_eq!(h.state().drones[0].current, K::ExtPause.to_wire());
    h.run(0.2);
    assert_eq!(h.reply(p, 1).unwrap().0, SwarmResult::Success);
    assert_eq!(h.reply(after, 1).unwrap().0, SwarmResult::Success);
}

/// At rest only when a tick would just refresh the state: not while a command
/// runs or waits in the queue, a reply waits to be published, or the LEDs are
/// behind the hardware drone's colour.
#[test]
fn at_rest_only_with_nothing_to_fly_answer_or_show() {
    let mut h = H::new(2);
    h.run(0.2);
    assert!(h.swarm.at_rest(), "on the ground, nothing asked");
    let p = h.send(1, K::ExtPause, |c| c.f[0] = 0.5);
    let queued = h.send(1, K::ExtPause, |c| c.f[0] = 0.2);
    assert!(!h.swarm.at_rest(), "a pause running, another queued");
    h.run(0.6);
    assert!(h.answered(p, 1) && !h.answered(queued, 1));
    assert!(!h.swarm.at_rest(), "the queued pause runs");
    h.run(0.3);
    assert!(h.answered(queued, 1));
    assert!(h.swarm.at_rest());
    // A reply not yet published.
    let c = SwarmCommand {
        request_id: 999,
        client: 7,
        drone: ALL_DRONES,
        kind: K::ExtCheckAllIdle.to_wire(),
        ..SwarmCommand::default()
    };
    h.swarm.handle_command(&c, h.now);
    assert!(!h.swarm.at_rest(), "replies waiting");
    h.pump();
    assert!(h.swarm.at_rest());
    // Two colours within the LEDs' 100 ms: the second waits for the next write.
    for rgb in [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
        let c = h.send(1, K::ExtColor, |c| {
            c.flags = swarm_flags::HAS_EXT1;
            c.f[4..7].copy_from_slice(&rgb);
            c.f[0] = 0.0;
        });
        assert!(h.run_until(1.0, |h| h.answered(c, 1)));
    }
    assert!(h.swarm.drone(0).idle() && h.swarm.drone(1).idle());
    assert!(!h.swarm.at_rest(), "the LEDs behind the colour");
    h.run(0.2);
    assert!(h.swarm.at_rest());
    // The other drone's colour is not on the hardware.
    h.send(2, K::ExtColor, |c| {
        c.flags = swarm_flags::HAS_EXT1;
        c.f[4..7].copy_from_slice(&[0.0, 0.0, 1.0]);
        c.f[0] = 0.0;
    });
    assert!(h.swarm.at_rest());
}

#[test]
fn colours_fade_and_reach_the_hardware() {
    let mut h = H::new(2);
    let c = h.send(1, K::ExtColor, |c| {
        c.flags = swarm_flags::HAS_EXT1;
        c.f[4..7].copy_from_slice(&[1.0, 0.0, 0.5]);
        c.f[0] = 1.0;
    });
    h.run(0.5);
    let col = h.state().drones[0].color;
    assert!(
        (col[0] - 0.5).abs() < 0.05 && (col[2] - 0.25).abs() < 0.03,
        "{col:?}"
    );
    h.run(0.6);
    assert_eq!(h.reply(c, 1).unwrap().0, SwarmResult::Success);
    assert_eq!(h.state().drones[0].color, [1.0, 0.0, 0.5]);
    h.run(0.2);
    let leds: Vec<(String, u8)> = h
        .hardware
        .iter()
        .filter(|r| r.op == HardwareOp::LedSet.to_wire())
        .map(|r| (r.name.as_str().to_string(), r.value))
        .collect();
    assert!((3..=40).contains(&leds.len()), "{leds:?}");
    let last = |name: &str| leds.iter().rev().find(|(n, _)| n == name).unwrap().1;
    assert_eq!((last("red"), last("green"), last("blue")), (255, 0, 128));
    // A gradient on the other drone: not the hardware drone, nothing sent.
    let n = h.hardware.len();
    let g = h.send(2, K::ExtColorGradient, |c| {
        c.flags = swarm_flags::HAS_EXT1 | swarm_flags::HAS_EXT2;
        c.f[4..7].copy_from_slice(&[0.0, 0.0, 1.0]);
        c.f[8..11].copy_from_slice(&[0.0, 1.0, 0.0]);
        c.f[0] = 0.5;
    });
    assert_eq!(h.state().drones[1].color, [0.0, 0.0, 1.0]);
    h.run(0.6);
    assert_eq!(h.reply(g, 2).unwrap().0, SwarmResult::Success);
    assert_eq!(h.state().drones[1].color, [0.0, 1.0, 0.0]);
    assert_eq!(h.hardware.len(), n);
    // Text: two LCD lines for the hardware drone.
    let t = h.send(1, K::ExtText, |c| {
        c.text = FixedStr::new("Hello swarm, drone 1")
    });
    assert_eq!(h.reply(t, 1).unwrap().0, SwarmResult::Success);
    let lcd: Vec<(u8, String)> = h
        .hardware
        .iter()
        .filter(|r| r.op == HardwareOp::Lcd.to_wire())
        .map(|r| (r.sub_op, r.text.as_str().to_string()))
        .collect();
    assert_eq!(
        lcd,
        [
            (LcdOp::WriteLine0.to_wire(), "Hello swarm, dro".to_string()),
            (LcdOp::WriteLine1.to_wire(), "ne 1".to_string())
        ]
    );
}

fn play(h: &mut H, looping: bool, use_pos: bool) -> u32 {
    h.send(1, K::ExtPlaybackAnim, |c| {
        c.int1 = 0;
        c.int2 = -1;
        c.f[..4].copy_from_slice(&[
            f32::from(u8::from(looping)),
            1.0,
            f32::from(u8::from(use_pos)),
            1.0,
        ]);
    })
}

#[test]
fn an_animation_loops_until_cancelled_then_finishes_its_loop() {
    let mut h = H::new(1);
    h.take_off(1);
    let a = play(&mut h, true, true);
    h.run(0.5);
    let s = h.state();
    assert_eq!(s.drones[0].current, K::ExtPlaybackAnim.to_wire());
    assert_eq!(s.drones[0].anim_frame, 0);
    assert!(
        (s.drones[0].target[0] - 2.0).abs() < 0.2,
        "{:?}",
        s.drones[0].target
    );
    h.run(0.7);
    assert_eq!(h.state().drones[0].anim_frame, 1);
    h.run(5.0);
    assert!(!h.answered(a, 1), "looping");
    // Colour follows the keyframes.
    let col = h.state().drones[0].color;
    assert!((col.iter().sum::<f32>() - 1.0).abs() < 0.01, "{col:?}");
    // The vehicle chases the animation.
    let max_x = h.fleet.vehicles[0].pos[0];
    assert!(max_x >= 0.0);
    let cancel = h.send(1, K::ExtAnimCancelLoop, |_| {});
    assert_eq!(h.reply(cancel, 1).unwrap().0, SwarmResult::Success);
    assert!(!h.answered(a, 1), "finishes the current loop");
    assert!(h.run_until(2.1, |h| h.answered(a, 1)));
    assert_eq!(h.reply(a, 1).unwrap().0, SwarmResult::Success);
    assert_eq!(h.state().drones[0].color, [0.0, 0.0, 1.0]);
    let gotos = h
        .sent_kinds(11)
        .iter()
        .filter(|k| **k == CommandKind::GoTo)
        .count();
    assert!(gotos > 50, "streamed: {gotos}");
}

#[test]
fn a_single_play_finishes_at_the_last_frame_and_speed_and_time_can_change() {
    let mut h = H::new(1);
    let a = play(&mut h, false, false); // colours only: no flying needed
    h.run(1.0);
    assert!(!h.answered(a, 1));
    let speed = h.send(1, K::ExtAnimAdjPlaybackSpeed, |c| c.f[0] = 2.0);
    assert_eq!(h.reply(speed, 1).unwrap().0, SwarmResult::Success);
    assert!(
        h.run_until(0.6, |h| h.answered(a, 1)),
        "1 s left at double speed"
    );
    assert_eq!(h.reply(a, 1).unwrap().0, SwarmResult::Success);
    let t = h.send(1, K::SetAnimPlaybackTime, |c| c.f[0] = 1.0);
    assert_eq!(
        h.reply(t, 1),
        Some((SwarmResult::Refused, "no animation playing".into()))
    );
    let b = play(&mut h, false, false);
    let t = h.send(1, K::SetAnimPlaybackTime, |c| c.f[0] = 1.9);
    assert_eq!(h.reply(t, 1).unwrap().0, SwarmResult::Success);
    let i = h.send(1, K::SetAnimColorIntensity, |c| c.f[0] = 0.5);
    assert_eq!(h.reply(i, 1).unwrap().0, SwarmResult::Success);
    assert!(h.run_until(0.3, |h| h.answered(b, 1)));
    assert_eq!(h.state().drones[0].color, [0.0, 0.0, 0.5]);
    // Manual colour mode ignores the animation's colours.
    let m = h.send(1, K::ManualColorMode, |c| c.int1 = 1);
    assert_eq!(h.reply(m, 1).unwrap().0, SwarmResult::Success);
    let c = play(&mut h, false, false);
    h.run(1.0);
    assert_eq!(h.state().drones[0].color, [0.0, 0.0, 0.5]);
    assert!(h.run_until(1.5, |h| h.answered(c, 1)));
}

#[test]
fn animations_are_checked_on_receipt() {
    let mut h = H::new(2);
    h.swarm.anims = AnimLibrary::new("/nonexistent");
    let a = play(&mut h, false, false);
    assert_eq!(
        h.reply(a, 1),
        Some((SwarmResult::Refused, "no animation for drone 1".into()))
    );
    h.swarm.anims_mut().insert(1, anim());
    let b = h.send(1, K::ExtPlaybackAnim, |c| {
        c.int1 = 5;
        c.f[1] = 1.0;
    });
    assert_eq!(
        h.reply(b, 1),
        Some((
            SwarmResult::Refused,
            "first frame 5 beyond the 3 frames".into()
        ))
    );
    let c = h.send(1, K::ExtAnimCancelLoop, |_| {});
    assert_eq!(
        h.reply(c, 1),
        Some((SwarmResult::Refused, "no animation playing".into()))
    );
    // Flying an animation needs a flying drone.
    let d = play(&mut h, true, true);
    assert_eq!(
        h.reply(d, 1),
        Some((SwarmResult::Refused, "not flying: take off first".into()))
    );
}

#[test]
fn check_all_idle_answers_per_drone() {
    let mut h = H::new(3);
    h.send(2, K::ExtPause, |c| c.f[0] = 5.0);
    let r = h.send(ALL_DRONES, K::ExtCheckAllIdle, |_| {});
    let answers: Vec<(u16, i32)> = h
        .replies_to(r)
        .iter()
        .map(|r| {
            assert_eq!(r.result().unwrap(), SwarmResult::IdleState);
            (r.drone, r.value)
        })
        .collect();
    assert_eq!(answers, [(1, 1), (2, 0), (3, 1)]);
    // Global commands that cannot fail are answered once, for every drone.
    let b = h.send(ALL_DRONES, K::ExtSetBoundingBox, |c| {
        c.flags = swarm_flags::HAS_EXT1;
        c.f[..3].copy_from_slice(&[1.0, 1.0, 1.0]);
    });
    assert_eq!(h.replies_to(b).len(), 1);
    assert_eq!(h.replies_to(b)[0].drone, ALL_DRONES);
    assert_eq!(h.reply(b, ALL_DRONES).unwrap().0, SwarmResult::Success);
    assert!((0..3).all(|i| h.swarm.drone(i).bbox.is_some()));
    let t = h.send(ALL_DRONES, K::ExtTimecode, |c| c.int1 = 100);
    assert_eq!(h.replies_to(t).len(), 1);
    assert_eq!(h.counter("ext_timecode", "success"), 1);
    let one = h.send(2, K::ExtCheckAllIdle, |_| {});
    assert_eq!(h.replies_to(one).len(), 1);
    assert_eq!(h.replies_to(one)[0].value, 0);
}

#[test]
fn the_bounding_box_clamps_waypoints() {
    let mut h = H::new(1);
    h.take_off(1);
    let b = h.send(1, K::ExtSetBoundingBox, |c| {
        c.flags = swarm_flags::HAS_EXT1;
        c.f[4..7].copy_from_slice(&[-5.0, -5.0, 1.0]);
        c.f[..3].copy_from_slice(&[5.0, 5.0, 4.0]);
    });
    assert_eq!(h.reply(b, 1).unwrap().0, SwarmResult::Success);
    let w = h.waypoint(1, [50.0, 0.0, 10.0]);
    assert_eq!(h.state().drones[0].target, [5.0, 0.0, 4.0]);
    assert!(h.run_until(20.0, |h| h.answered(w, 1)));
    assert_eq!(h.reply(w, 1).unwrap().0, SwarmResult::Success);
    assert!(close(h.state().drones[0].tracking, [5.0, 0.0, 4.0], 0.5));
}

#[test]
fn the_bounding_box_refuses_waypoints_when_configured() {
    let mut h = H::with(1, "bounding_box = \"refuse\"");
    h.take_off(1);
    h.send(1, K::ExtSetBoundingBox, |c| {
        c.flags = swarm_flags::HAS_EXT1;
        c.f[4..7].copy_from_slice(&[-5.0, -5.0, 1.0]);
        c.f[..3].copy_from_slice(&[5.0, 5.0, 4.0]);
    });
    let w = h.waypoint(1, [50.0, 0.0, 3.0]);
    assert_eq!(
        h.reply(w, 1),
        Some((SwarmResult::Refused, "outside the bounding box".into()))
    );
    let ok = h.waypoint(1, [4.0, 0.0, 3.0]);
    assert!(h.run_until(10.0, |h| h.answered(ok, 1)));
    assert_eq!(h.reply(ok, 1).unwrap().0, SwarmResult::Success);
}

#[test]
fn a_geofence_goes_to_the_arbiter_and_limits_the_queue() {
    let mut h = H::new(1);
    h.take_off(1);
    let g = h.send(1, K::SetGeofence, |c| {
        c.flags |= swarm_flags::HAS_EXT1;
        c.f[4..7].copy_from_slice(&[-10.0, -10.0, 0.0]);
        c.f[..3].copy_from_slice(&[10.0, 10.0, 20.0]);
    });
    assert_eq!(h.reply(g, 1).unwrap().0, SwarmResult::Success);
    let fence = h.geofences.last().unwrap();
    assert_eq!(fence.vehicle_id, 11);
    assert_eq!(fence.enabled, 1);
    assert_eq!(fence.source, CommandSource::SwarmQueue.to_wire());
    assert_ne!(fence.request_id, 0);
    let rings = fence.polygons().unwrap();
    assert_eq!(rings.len(), 1);
    assert_eq!(rings[0].1.len(), 4);
    let site = h.swarm.settings().site;
    let [x, y] = site.to_site_xy(rings[0].1[2][0], rings[0].1[2][1]);
    assert!((x - 10.0).abs() < 1e-3 && (y - 10.0).abs() < 1e-3);
    assert!((fence.ceiling_m - 20.0).abs() < 0.01 && fence.floor_m.abs() < 0.01);
    let p = h.send(1, K::SetGeofencePosition, |c| {
        c.f[..3].copy_from_slice(&[100.0, 0.0, 10.0])
    });
    assert_eq!(h.reply(p, 1).unwrap().0, SwarmResult::Success);
    let w = h.waypoint(1, [0.0, 50.0, 3.0]);
    assert_eq!(h.state().drones[0].target, [90.0, 10.0, 3.0]);
    let halt = h.send(1, K::ExtHalt, |_| {});
    assert_eq!(h.reply(w, 1).unwrap().0, SwarmResult::Refused);
    assert_eq!(h.reply(halt, 1).unwrap().0, SwarmResult::Success);
    let bad = h.send(1, K::ReconfigureGeofence, |c| {
        c.flags |= swarm_flags::HAS_EXT1;
        c.f[4..7].copy_from_slice(&[0.0, 0.0, 0.0]);
        c.f[..3].copy_from_slice(&[0.0, 10.0, 20.0]);
    });
    assert_eq!(
        h.reply(bad, 1),
        Some((SwarmResult::Refused, "geofence box is empty".into()))
    );
}

#[test]
fn emergency_mode_stops_under_the_queues_own_source_and_withdraws_only_its_own() {
    let mut h = H::new(2);
    h.take_off(1);
    let w = h.waypoint(1, [20.0, 0.0, 3.0]);
    h.run(0.5);
    let e = h.send(1, K::EmergencyMode, |c| c.int1 = 1);
    assert_eq!(
        h.reply(w, 1),
        Some((SwarmResult::Refused, "emergency mode".into()))
    );
    assert_eq!(h.reply(e, 1).unwrap().0, SwarmResult::Success);
    let stop = h.sent.last().unwrap();
    assert_eq!(stop.kind, CommandKind::EmergencyStop.to_wire());
    assert_eq!(stop.source, CommandSource::SwarmQueue.to_wire());
    assert!(h.fleet.vehicles[0].emergency_by(CommandSource::SwarmQueue));
    assert!(h.state().drones[0].flags & drone_flags::EMERGENCY != 0);
    let x = h.fleet.vehicles[0].pos[0];
    h.run(1.0);
    assert!((h.fleet.vehicles[0].pos[0] - x).abs() < 0.01, "holding");
    let refused = h.waypoint(1, [0.0, 0.0, 3.0]);
    assert_eq!(
        h.reply(refused, 1),
        Some((SwarmResult::Refused, "emergency mode".into()))
    );
    let land = h.send(1, K::ExtGoHomeAtPosition, |_| {});
    assert_eq!(
        h.reply(land, 1),
        Some((SwarmResult::Refused, "emergency mode".into()))
    );
    // Colour and text still work; the other drone is not affected.
    let other = h.send(2, K::ExtPause, |c| c.f[0] = 0.0);
    assert_eq!(h.reply(other, 2).unwrap().0, SwarmResult::Success);
    // A DJI pilot stops the same vehicle too.
    h.fleet.vehicles[0].emergency_sources |= 1 << CommandSource::DjiDrc.to_wire();
    let before = h.sent.len();
    let end = h.send(1, K::EmergencyMode, |c| c.int1 = 0);
    assert_eq!(h.reply(end, 1).unwrap().0, SwarmResult::Success);
    let sent: Vec<_> = h.sent[before..].iter().collect();
    assert_eq!(sent.len(), 1, "{sent:?}");
    assert_eq!(sent[0].kind, CommandKind::ReleaseEmergency.to_wire());
    assert_eq!(sent[0].source, CommandSource::SwarmQueue.to_wire());
    assert!(
        h.sent
            .iter()
            .all(|c| c.kind != CommandKind::ReleaseFlightAuthority.to_wire()),
        "never releases authority to end a stop"
    );
    assert!(h.state().drones[0].flags & drone_flags::EMERGENCY == 0);
    // The pilot's stop holds: the vehicle still refuses to move.
    let v = &h.fleet.vehicles[0];
    assert!(!v.emergency_by(CommandSource::SwarmQueue));
    assert!(v.emergency_by(CommandSource::DjiDrc));
    let blocked = h.waypoint(1, [0.0, 0.0, 3.0]);
    assert!(h.run_until(5.0, |h| h.answered(blocked, 1)));
    let (result, why) = h.reply(blocked, 1).unwrap();
    assert_eq!(result, SwarmResult::Refused);
    assert!(why.contains("emergency"), "{why}");
    // A second end has no stop of the queue's to withdraw: the arbiter's answer.
    let again = h.send(1, K::EmergencyMode, |c| c.int1 = 0);
    assert_eq!(h.reply(again, 1).unwrap().0, SwarmResult::Refused);
    // Once an operator cleared the pilot's stop, the drone flies again.
    let clear =
        VehicleCommand::new(11, CommandSource::Operator, 901, &Command::ClearEmergency).unwrap();
    let now = h.now;
    h.fleet.deliver(&mut h.swarm, &[clear], now);
    assert!(!h.fleet.vehicles[0].emergency());
    let back = h.waypoint(1, [0.0, 0.0, 3.0]);
    assert!(h.run_until(20.0, |h| h.answered(back, 1)));
    assert_eq!(h.reply(back, 1).unwrap().0, SwarmResult::Success);
}

#[test]
fn a_refused_emergency_stop_does_not_set_the_flag() {
    let mut h = H::new(1);
    h.take_off(1);
    h.fleet.vehicles[0].refuse.push(CommandKind::EmergencyStop);
    let e = h.send(1, K::EmergencyMode, |c| c.int1 = 1);
    assert_eq!(h.reply(e, 1).unwrap().0, SwarmResult::Refused);
    assert!(h.state().drones[0].flags & drone_flags::EMERGENCY == 0);
    let w = h.waypoint(1, [2.0, 0.0, 3.0]);
    assert!(h.run_until(10.0, |h| h.answered(w, 1)));
    assert_eq!(h.reply(w, 1).unwrap().0, SwarmResult::Success);
}

#[test]
fn an_operator_clear_ends_the_queues_emergency_mode() {
    let mut h = H::new(1);
    h.take_off(1);
    let e = h.send(1, K::EmergencyMode, |c| c.int1 = 1);
    assert_eq!(h.reply(e, 1).unwrap().0, SwarmResult::Success);
    let clear =
        VehicleCommand::new(11, CommandSource::Operator, 900, &Command::ClearEmergency).unwrap();
    let now = h.now;
    h.fleet.deliver(&mut h.swarm, &[clear], now);
    assert!(h.state().drones[0].flags & drone_flags::EMERGENCY == 0);
    let w = h.waypoint(1, [2.0, 0.0, 3.0]);
    assert!(h.run_until(10.0, |h| h.answered(w, 1)));
    assert_eq!(h.reply(w, 1).unwrap().0, SwarmResult::Success);
}

fn box_fence(h: &mut H, max: [f32; 3]) -> u32 {
    h.send(1, K::SetGeofence, |c| {
        c.flags |= swarm_flags::HAS_EXT1;
        c.f[4..7].copy_from_slice(&[-10.0, -10.0, 0.0]);
        c.f[..3].copy_from_slice(&max);
    })
}

/// Hands the drone's vehicle events as its arbiter would publish them.
fn arbiter_says(h: &mut H, kind: ArbiterEventKind, request_id: u32) {
    let e = ArbiterEvent {
        vehicle_id: 11,
        kind: kind.to_wire(),
        source: CommandSource::SwarmQueue.to_wire(),
        request_id,
        detail: FixedStr::new("ring crosses itself"),
        ..ArbiterEvent::default()
    };
    let now = h.now;
    h.swarm.handle_event(0, &e, now);
    h.pump();
}

#[test]
fn a_geofence_is_answered_only_by_the_arbiters_decision_on_it() {
    let mut h = H::new(1);
    h.fleet.vehicles[0].ignore_fences = true;
    let g = box_fence(&mut h, [10.0, 10.0, 20.0]);
    let sent = h.geofences.last().unwrap().request_id;
    assert!(!h.answered(g, 1), "no answer before the arbiter's");
    assert!(!h.swarm.at_rest(), "waiting for the arbiter");
    // Another request's decision, another source's, and the wrong vehicle: no answer.
    arbiter_says(&mut h, ArbiterEventKind::GeofenceUpdated, sent + 1);
    let mut other = ArbiterEvent {
        vehicle_id: 11,
        kind: ArbiterEventKind::GeofenceUpdated.to_wire(),
        source: CommandSource::ShotEngine.to_wire(),
        request_id: sent,
        ..ArbiterEvent::default()
    };
    let now = h.now;
    h.swarm.handle_event(0, &other, now);
    other.source = CommandSource::SwarmQueue.to_wire();
    other.vehicle_id = 12;
    h.swarm.handle_event(0, &other, now);
    h.pump();
    assert!(!h.answered(g, 1));
    assert_eq!(h.swarm.drone(0).fence, None);
    arbiter_says(&mut h, ArbiterEventKind::GeofenceUpdated, sent);
    assert_eq!(h.reply(g, 1).unwrap().0, SwarmResult::Success);
    assert!(h.swarm.drone(0).fence.is_some());
    assert_eq!(h.replies_to(g).len(), 1);
    // Refused: a failure with the arbiter's reason, and the fence it had stays.
    let bad = box_fence(&mut h, [30.0, 30.0, 20.0]);
    let sent_bad = h.geofences.last().unwrap().request_id;
    assert_ne!(sent_bad, sent);
    arbiter_says(&mut h, ArbiterEventKind::GeofenceInvalid, sent_bad);
    let (result, why) = h.reply(bad, 1).unwrap();
    assert_eq!(result, SwarmResult::Refused);
    assert!(why.contains("ring crosses"), "{why}");
    assert_eq!(h.swarm.drone(0).fence.unwrap().max, [10.0, 10.0, 20.0]);
    // Never answered: a timeout after two seconds, not before.
    let late = box_fence(&mut h, [20.0, 20.0, 20.0]);
    h.run(1.8);
    assert!(!h.answered(late, 1));
    h.run(0.3);
    assert_eq!(h.reply(late, 1).unwrap().0, SwarmResult::Timeout);
    assert_eq!(h.swarm.drone(0).fence.unwrap().max, [10.0, 10.0, 20.0]);
    assert!(h.swarm.at_rest());
}

#[test]
fn a_geofence_the_arbiter_refuses_is_a_failure() {
    let mut h = H::new(1);
    h.fleet.vehicles[0].refuse_fences = true;
    let g = box_fence(&mut h, [10.0, 10.0, 20.0]);
    let (result, why) = h.reply(g, 1).unwrap();
    assert_eq!(result, SwarmResult::Refused);
    assert!(why.contains("test refusal"), "{why}");
    assert_eq!(h.swarm.drone(0).fence, None);
    // The queue does not clamp to a fence the arbiter does not enforce.
    h.take_off(1);
    let w = h.waypoint(1, [15.0, 0.0, 3.0]);
    assert_eq!(h.state().drones[0].target, [15.0, 0.0, 3.0]);
    assert!(h.run_until(20.0, |h| h.answered(w, 1)));
}

#[test]
fn unknown_drones_bad_parameters_and_privilege_are_refused() {
    let mut h = H::new(2);
    let r = h.send(9, K::ExtPause, |c| c.f[0] = 1.0);
    assert_eq!(
        h.reply(r, 9),
        Some((SwarmResult::Refused, "unknown drone".into()))
    );
    let r = h.send(1, K::ExtPause, |c| c.f[0] = f32::NAN);
    assert_eq!(h.reply(r, 1).unwrap().0, SwarmResult::Refused);
    let r = h.send(1, K::ExtColor, |c| c.f[4] = 1.0);
    assert!(h.reply(r, 1).unwrap().1.contains("EXT_PARAM_1"));
    let r = h.send(1, K::MotorsCmd, |c| {
        c.int1 = 1;
        c.flags = 0;
    });
    assert_eq!(
        h.reply(r, 1),
        Some((
            SwarmResult::Refused,
            "privileged command from an unprivileged client".into()
        ))
    );
    let raw = SwarmCommand {
        request_id: 99,
        drone: 1,
        kind: 0xEE,
        ..SwarmCommand::default()
    };
    h.swarm.handle_command(&raw, h.now);
    h.pump();
    assert_eq!(h.reply(99, 1).unwrap().0, SwarmResult::Refused);
    for k in [K::WakeUp, K::EnableSafetyPilot, K::ResetTrackingToSetup] {
        let r = h.send(1, k, |_| {});
        assert_eq!(
            h.reply(r, 1),
            Some((
                SwarmResult::Refused,
                "not meaningful for a MAVLink drone".into()
            )),
            "{k}"
        );
    }
    assert_eq!(h.counter("unknown", "refused"), 1);
    assert!(h.sent.is_empty(), "nothing reached a vehicle");
}

#[test]
fn a_refused_ack_fails_the_command_and_the_queue_moves_on() {
    let mut h = H::new(1);
    h.fleet.vehicles[0].refuse.push(CommandKind::Arm);
    let t = h.send(1, K::ExtGoExternal, |_| {});
    let p = h.send(1, K::ExtPause, |c| c.f[0] = 0.0);
    h.run(0.2);
    assert_eq!(
        h.reply(t, 1),
        Some((
            SwarmResult::Refused,
            "arm refused: denied: test refusal".into()
        ))
    );
    assert_eq!(h.reply(p, 1).unwrap().0, SwarmResult::Success);
    // A vehicle-answered immediate command: the reply carries the refusal too.
    h.fleet.vehicles[0].refuse.clear();
    h.fleet.vehicles[0].refuse.push(CommandKind::SetHome);
    let home = h.send(1, K::ExtSetHomePositionCoordinate, |c| c.f[0] = 1.0);
    assert_eq!(
        h.reply(home, 1),
        Some((
            SwarmResult::Refused,
            "set_home refused: denied: test refusal".into()
        ))
    );
}

#[test]
fn commands_time_out() {
    let mut h = H::with(
        1,
        "[timeouts]\ntakeoff_s = 3\nwaypoint_base_s = 2\nack_s = 1",
    );
    h.fleet.vehicles[0].ignore.push(CommandKind::Takeoff);
    let t = h.send(1, K::ExtGoExternal, |_| {});
    h.run(2.9);
    assert!(!h.answered(t, 1));
    h.run(0.2);
    assert_eq!(
        h.reply(t, 1),
        Some((
            SwarmResult::Timeout,
            "ext_go_external not finished in 3 s".into()
        ))
    );
    h.fleet.vehicles[0].ignore.clear();
    h.take_off(1);
    // A vehicle that does not move: 2 s + 3 × 4 m / 2 m/s = 8 s.
    h.fleet.vehicles[0].ignore.push(CommandKind::GoTo);
    let w = h.waypoint(1, [4.0, 0.0, 2.5]);
    h.run(7.9);
    assert!(!h.answered(w, 1));
    h.run(0.2);
    assert_eq!(h.reply(w, 1).unwrap().0, SwarmResult::Timeout);
    h.fleet.vehicles[0].ignore.push(CommandKind::SetYaw);
    let y = h.send(1, K::ExtVehicleCmd, |c| {
        c.int1 = 1;
        c.f[0] = 45.0;
    });
    h.run(0.9);
    assert!(!h.answered(y, 1));
    h.run(0.2);
    assert_eq!(
        h.reply(y, 1),
        Some((SwarmResult::Timeout, "no answer from the vehicle".into()))
    );
    assert_eq!(h.counter("ext_go_external", "timeout"), 1);
}

#[test]
fn go_home_flies_home_and_lands() {
    let mut h = H::new(1);
    h.take_off(1);
    let w = h.waypoint(1, [6.0, 6.0, 5.0]);
    assert!(h.run_until(20.0, |h| h.answered(w, 1)));
    let home = h.send(1, K::ExtSetHomePositionCoordinate, |c| {
        c.f[..4].copy_from_slice(&[2.0, 1.0, 0.0, 90.0])
    });
    assert_eq!(h.reply(home, 1).unwrap().0, SwarmResult::Success);
    let g = h.send(1, K::ExtGoHome, |_| {});
    assert_eq!(h.state().drones[0].target, [2.0, 1.0, 5.0]);
    assert!(h.run_until(40.0, |h| h.answered(g, 1)));
    assert_eq!(h.reply(g, 1).unwrap().0, SwarmResult::Success);
    let v = &h.fleet.vehicles[0];
    assert!(
        (v.pos[0] - 2.0).abs() < 0.6 && (v.pos[1] - 1.0).abs() < 0.6,
        "{:?}",
        v.pos
    );
    assert!(!v.armed && v.alt_rel() < 0.01);
    assert_eq!(
        h.state().drones[0].drone_state,
        DroneState::OnGround.to_wire()
    );
    let kinds = h.sent_kinds(11);
    assert_eq!(kinds.last(), Some(&CommandKind::Land));
    assert!(kinds.contains(&CommandKind::SetHome));
    // On the ground it finishes at once.
    let g2 = h.send(1, K::ExtGoHome, |_| {});
    assert_eq!(
        h.reply(g2, 1),
        Some((SwarmResult::Success, "on the ground".into()))
    );
}

#[test]
fn landing_states_are_reported_and_land_here_finishes_landed() {
    let mut h = H::new(1);
    h.take_off(1);
    let w = h.waypoint(1, [0.0, 0.0, 5.0]);
    assert!(h.run_until(20.0, |h| h.answered(w, 1)));
    let l = h.send(1, K::ExtGoHomeAtPosition, |_| {});
    h.run(0.5);
    assert_eq!(
        h.state().drones[0].drone_state,
        DroneState::LandingFast.to_wire()
    );
    assert!(h.run_until(10.0, |h| h.fleet.vehicles[0].alt_rel() < 1.5));
    h.step();
    assert_eq!(
        h.state().drones[0].drone_state,
        DroneState::LandingSlow.to_wire()
    );
    assert!(h.run_until(10.0, |h| h.answered(l, 1)));
    assert_eq!(h.reply(l, 1).unwrap().0, SwarmResult::Success);
}

#[test]
fn inactive_drones_refuse_motion_but_land() {
    let mut h = H::new(1);
    h.take_off(1);
    let off = h.send(1, K::ExtSetActive, |c| c.int1 = 0);
    assert_eq!(h.reply(off, 1).unwrap().0, SwarmResult::Success);
    assert!(h.state().drones[0].flags & drone_flags::ACTIVE == 0);
    let w = h.waypoint(1, [1.0, 0.0, 3.0]);
    assert_eq!(
        h.reply(w, 1),
        Some((SwarmResult::Refused, "inactive".into()))
    );
    let c = h.send(1, K::ExtPause, |c| c.f[0] = 0.0);
    assert_eq!(h.reply(c, 1).unwrap().0, SwarmResult::Success);
    let l = h.send(1, K::ExtGoHomeAtPosition, |_| {});
    assert!(h.run_until(10.0, |h| h.answered(l, 1)));
    assert_eq!(h.reply(l, 1).unwrap().0, SwarmResult::Success);
    let on = h.send(1, K::SetActive, |c| c.int1 = 1);
    assert_eq!(h.reply(on, 1).unwrap().0, SwarmResult::Success);
    assert!(h.state().drones[0].flags & drone_flags::ACTIVE != 0);
}

#[test]
fn a_manual_target_replaces_the_current_command_now() {
    let mut h = H::new(1);
    h.take_off(1);
    let w = h.waypoint(1, [20.0, 0.0, 3.0]);
    let q = h.waypoint(1, [0.0, 0.0, 3.0]);
    h.run(0.5);
    let m = h.send(1, K::SetManualTarget, |c| {
        c.f[..3].copy_from_slice(&[0.0, 4.0, 3.0])
    });
    assert_eq!(
        h.reply(w, 1),
        Some((SwarmResult::Refused, "replaced by a manual target".into()))
    );
    assert_eq!(h.state().drones[0].current, K::SetManualTarget.to_wire());
    assert_eq!(h.state().drones[0].queue_depth, 1, "the queue stays");
    assert!(h.run_until(20.0, |h| h.answered(q, 1)));
    assert_eq!(h.reply(m, 1).unwrap().0, SwarmResult::Success);
    assert_eq!(h.reply(q, 1).unwrap().0, SwarmResult::Success);
}

#[test]
fn motors_rotation_home_and_recorded_commands() {
    let mut h = H::new(1);
    let arm = h.send(1, K::MotorsCmd, |c| c.int1 = 1);
    assert_eq!(h.reply(arm, 1).unwrap().0, SwarmResult::Success);
    assert!(h.fleet.vehicles[0].armed);
    h.step();
    assert_eq!(
        h.state().drones[0].drone_state,
        DroneState::LandingMotorsOff.to_wire()
    );
    let disarm = h.send(1, K::MotorsCmd, |c| c.int1 = 0);
    assert_eq!(h.reply(disarm, 1).unwrap().0, SwarmResult::Success);
    assert!(!h.fleet.vehicles[0].armed);
    // Rotation: relative 30° CCW = 30° anticlockwise on the compass.
    h.fleet.vehicles[0].heading = 90.0;
    let r = h.send(1, K::ExtVehicleCmd, |c| {
        c.int1 = 1;
        c.f[0] = 30.0;
    });
    assert_eq!(h.reply(r, 1), Some((SwarmResult::Success, String::new())));
    assert_eq!(h.fleet.vehicles[0].heading, 60.0);
    let r = h.send(1, K::ExtVehicleCmd, |c| {
        c.int1 = 2;
        c.f[0] = 180.0;
    });
    assert_eq!(h.reply(r, 1).unwrap().0, SwarmResult::Success);
    assert_eq!(h.fleet.vehicles[0].heading, 270.0);
    assert_eq!(h.state().drones[0].relative_rotation_deg, 180.0);
    let n = h.sent.len();
    let void = h.send(1, K::ExtVehicleCmd, |c| c.int1 = 4);
    assert_eq!(h.reply(void, 1).unwrap().0, SwarmResult::Success);
    assert_eq!(h.sent.len(), n, "a void command sends nothing");
    // Home: to the drone, to the setup (the autopilot's first home), to the animation.
    h.fleet.vehicles[0].pos = [3.0, 4.0, 0.0];
    h.step();
    let r = h.send(1, K::ResetHomePosition, |_| {});
    assert_eq!(h.reply(r, 1).unwrap().0, SwarmResult::Success);
    let home = h.fleet.vehicles[0].home;
    assert!(
        (home[0] - 3.0).abs() < 1e-3 && (home[1] - 4.0).abs() < 1e-3,
        "{home:?}"
    );
    let r = h.send(1, K::ResetHomeToSetup, |_| {});
    assert_eq!(h.reply(r, 1).unwrap().0, SwarmResult::Success);
    assert!(h.fleet.vehicles[0].home[0].abs() < 1e-3);
    let r = h.send(1, K::ResetAnimPositionToDrone, |_| {});
    assert_eq!(h.reply(r, 1).unwrap().0, SwarmResult::Success);
    let r = h.send(1, K::ResetHomePositionToAnim, |_| {});
    assert_eq!(h.reply(r, 1).unwrap().0, SwarmResult::Success);
    assert!(
        (h.fleet.vehicles[0].home[0] - 3.0).abs() < 1e-3,
        "animation start + offset"
    );
    for k in [
        K::ExtResetTrackingToFrame,
        K::ExtVideo,
        K::ExtVideoCmd,
        K::ExtTimecode,
        K::ExtTimecodeActive,
        K::CtrlMode,
        K::ColorMode,
        K::SetGroup,
        K::SetClockTimeout,
        K::ResetAnimPosition,
    ] {
        let r = h.send(1, k, |_| {});
        assert_eq!(h.reply(r, 1).unwrap().0, SwarmResult::Success, "{k}");
    }
}

#[test]
fn state_carries_pose_calibration_and_flags() {
    let mut h = H::new(2);
    h.fleet.vehicles[0].pos = [1.0, 2.0, 0.0];
    h.fleet.vehicles[0].heading = 0.0; // north
    h.step();
    let s = h.state();
    let d = &s.drones[0];
    assert!(close(d.tracking, [1.0, 2.0, 0.0], 1e-3));
    assert!((d.tracking_yaw_deg - 90.0).abs() < 1e-3);
    assert!(
        (d.quaternion[2] - (45f32).to_radians().sin()).abs() < 1e-4,
        "{:?}",
        d.quaternion
    );
    assert_eq!(d.target, d.tracking);
    assert_eq!(d.vehicle_id, 11);
    assert_eq!(
        d.flags,
        drone_flags::IDLE | drone_flags::ACTIVE | drone_flags::POSE_VALID
    );
    let r = h.send(1, K::SetCalibrationOffset, |c| {
        c.f[..3].copy_from_slice(&[0.5, 0.0, -0.25])
    });
    assert_eq!(h.reply(r, 1).unwrap().0, SwarmResult::Success);
    assert!(close(h.state().drones[0].tracking, [1.5, 2.0, -0.25], 1e-3));
    // No vehicle samples for a while: pose invalid, link down.
    h.now += 5_000_000_000;
    h.swarm.tick(h.now);
    let d = h.state().drones[1];
    assert_eq!(
        d.flags & (drone_flags::POSE_VALID | drone_flags::LINK_DOWN),
        drone_flags::LINK_DOWN
    );
    assert!(s.time_s > 0.0);
    // A state without a position fix keeps the last valid position.
    let mut nofix = h.fleet.vehicles[0].state(h.now);
    nofix.position_valid = 0;
    nofix.lat_deg = 0.0;
    nofix.lon_deg = 0.0;
    h.swarm.handle_state(0, &nofix, h.now);
    let d = h.state().drones[0];
    assert!(
        close(d.tracking, [1.5, 2.0, -0.25], 1e-3),
        "{:?}",
        d.tracking
    );
    assert_eq!(d.flags & drone_flags::POSE_VALID, 0);
    // A queue that never heard from its vehicle: DroneState NONE.
    let cfg = settings(1, "");
    let sw = Swarm::new(
        cfg,
        AnimLibrary::new("/x"),
        Metrics::new(&Stats::new(), &[1]),
        T0,
    );
    let mut st = SwarmState::default();
    sw.fill_state(T0, &mut st);
    assert_eq!(st.drones[0].drone_state, DroneState::None.to_wire());
    assert_eq!(
        st.drones[0].flags,
        drone_flags::IDLE | drone_flags::ACTIVE | drone_flags::LINK_DOWN
    );
}

#[test]
fn a_full_queue_refuses_and_replies_are_bounded() {
    let mut h = H::with(1, "queue_capacity = 3");
    let ids: Vec<u32> = (0..5)
        .map(|_| h.send(1, K::ExtPause, |c| c.f[0] = 10.0))
        .collect();
    // The first starts at once, three wait, the fifth is refused.
    assert!(!h.answered(ids[3], 1));
    assert_eq!(
        h.reply(ids[4], 1),
        Some((SwarmResult::Refused, "queue full".into()))
    );
    assert_eq!(h.state().drones[0].queue_depth, 3);
    assert_eq!(
        h.stats
            .gauge("skymesh_swarm_queue_depth", &[("drone", "1")])
            .get(),
        0.0,
        "gauges follow at the tick"
    );
    h.step();
    assert_eq!(
        h.stats
            .gauge("skymesh_swarm_queue_depth", &[("drone", "1")])
            .get(),
        3.0
    );
}

#[test]
fn many_drones_take_off_fly_and_answer() {
    let mut h = H::new(100);
    h.take_off(ALL_DRONES);
    let r = h.send(ALL_DRONES, K::ExtWaypoint, |c| {
        c.f[..3].copy_from_slice(&[0.0, 0.0, 4.0])
    });
    // Each drone flies to (0, 0, 4) from its own spot: the far ones need longer.
    assert!(h.run_until(200.0, |h| (1..=100).all(|d| h.answered(r, d))));
    assert!(h
        .replies_to(r)
        .iter()
        .all(|r| r.result().unwrap() == SwarmResult::Success));
}

/// The times (`h.now`) at which each GrabFlightAuthority went out while `f` ran.
fn grabs_during(h: &mut H, mut f: impl FnMut(&mut H) -> bool) -> Vec<u64> {
    let mut times = Vec::new();
    let mut seen = h.sent.len();
    while f(h) {
        h.step();
        let new = h.sent[seen..]
            .iter()
            .filter(|c| c.kind == CommandKind::GrabFlightAuthority.to_wire())
            .count();
        times.extend(std::iter::repeat_n(h.now, new));
        seen = h.sent.len();
    }
    times
}

/// Issue 42 finding 11: the arbiter brakes a position target whose source fell
/// silent for its authority timeout (5 s). A climb to 20 m takes 8 s: the queue keeps
/// its authority alive every second while climbing, and sends nothing at rest.
#[test]
fn a_takeoff_longer_than_the_authority_timeout_is_kept_alive() {
    let mut h = H::with(1, "takeoff_alt_m = 20\n");
    let r = h.send(1, K::ExtGoExternal, |_| {});
    let start = h.now;
    let grabs = grabs_during(&mut h, |h| {
        !h.answered(r, 1) && h.now - start < 20 * 1_000_000_000
    });
    assert_eq!(h.reply(r, 1), Some((SwarmResult::Success, String::new())));
    let took = (h.now - start) as f64 / 1e9;
    assert!(took > 7.0, "a climb longer than the timeout: {took:.1} s");
    let v = &h.fleet.vehicles[0];
    assert_eq!(v.target_brakes, 0, "never braked");
    assert!(v.alt_rel() > 19.4, "{}", v.alt_rel());
    assert_eq!(v.holder, Some(CommandSource::SwarmQueue));
    // One a second: the first a second after the Takeoff, none closer than 0.9 s nor
    // further apart than a second and a tick.
    assert!(grabs.len() >= 6, "{grabs:?}");
    for w in grabs.windows(2) {
        let gap = w[1] - w[0];
        assert!(
            (900_000_000..=1_000_000_000 + TICK_NS).contains(&gap),
            "keep-alive gap {gap} ns"
        );
    }
    // Each keep-alive is owned by the takeoff and answered: nothing piles up.
    assert!(h.swarm.drone(0).pending.is_empty());
    // At rest: nothing goes out, the authority lapses at the arbiter.
    let before = h.sent.len();
    h.run(8.0);
    assert_eq!(h.sent.len(), before, "{:?}", &h.sent[before..]);
    assert!(h.swarm.at_rest());
    assert_eq!(h.fleet.vehicles[0].holder, None);
}

/// The fake arbiter brakes a target whose source is quieter than its timeout: a
/// keep-alive slower than the arbiter's timeout does not keep the climb going.
#[test]
fn a_keepalive_slower_than_the_arbiters_timeout_is_braked() {
    let mut h = H::with(
        1,
        "takeoff_alt_m = 20\nauthority_keepalive_ms = 2500\n[timeouts]\ntakeoff_s = 10\n",
    );
    h.fleet.vehicles[0].authority_timeout_ns = 2_000_000_000;
    let r = h.send(1, K::ExtGoExternal, |_| {});
    assert!(h.run_until(15.0, |h| h.answered(r, 1)));
    assert_eq!(h.reply(r, 1).unwrap().0, SwarmResult::Timeout);
    let v = &h.fleet.vehicles[0];
    assert!(v.target_brakes >= 1);
    assert!(v.alt_rel() < 10.0, "stopped climbing: {}", v.alt_rel());
}

/// A 20 m leg at 2 m/s (10 s) is flown to the end; a higher source taking flight
/// authority during the next leg ends it at the next keep-alive (refused
/// `NoAuthority`), and the queue stops sending for that drone.
#[test]
fn a_long_waypoint_keeps_authority_until_a_higher_source_takes_it() {
    let mut h = H::new(1);
    h.take_off(1);
    let w = h.waypoint(1, [20.0, 0.0, 3.0]);
    let start = h.now;
    let grabs = grabs_during(&mut h, |h| {
        !h.answered(w, 1) && h.now - start < 30 * 1_000_000_000
    });
    assert_eq!(h.reply(w, 1), Some((SwarmResult::Success, String::new())));
    assert!(grabs.len() >= 8, "{grabs:?}");
    assert_eq!(h.fleet.vehicles[0].target_brakes, 0);

    let back = h.waypoint(1, [0.0, 0.0, 3.0]);
    h.run(1.5);
    let grab = VehicleCommand::new(
        11,
        CommandSource::Operator,
        902,
        &Command::GrabFlightAuthority,
    )
    .unwrap();
    let now = h.now;
    h.fleet.deliver(&mut h.swarm, &[grab], now);
    assert_eq!(h.fleet.vehicles[0].holder, Some(CommandSource::Operator));
    assert!(h.run_until(1.2, |h| h.answered(back, 1)));
    let (result, why) = h.reply(back, 1).unwrap();
    assert_eq!(result, SwarmResult::Refused);
    assert!(why.contains("no_authority"), "{why}");
    let before = h.sent.len();
    h.run(3.0);
    assert_eq!(h.sent.len(), before, "{:?}", &h.sent[before..]);
    assert!(h.swarm.drone(0).idle());
}
