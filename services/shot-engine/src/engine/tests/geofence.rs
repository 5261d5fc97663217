//! The app's geofence: validation and acks, the arbiter's `GeofenceSet`, updates,
//! clears, and the predictive check with its hold.

use skymesh_ipc_types::shot_api::shots::{NONE, ORBIT};
use skymesh_ipc_types::{AppGeofence, ArbiterEvent, ArbiterEventKind, FenceKind, GeofenceSet};

use super::*;

/// One metre of longitude here, degrees.
fn m_lon() -> f64 {
    M_LAT / LAT.to_radians().cos()
}

/// `[lat, lon]` `north_m`, `east_m` from the start.
fn pt(north_m: f64, east_m: f64) -> [f64; 2] {
    [LAT + north_m * M_LAT, LON + east_m * m_lon()]
}

/// A rectangle between the given norths and easts.
fn rect(n0: f64, n1: f64, e0: f64, e1: f64) -> Vec<[f64; 2]> {
    vec![pt(n0, e0), pt(n0, e1), pt(n1, e1), pt(n1, e0)]
}

/// An app polygon: `type`, `coord`, `subCoord`.
type Zone = (u8, Vec<[f64; 2]>, Vec<[f64; 2]>);

/// Keep-in ±100 m (hold line ±90 m) and a keep-out 30..50 m north (hold line
/// 25..55 m).
fn field() -> Vec<Zone> {
    vec![
        (
            0,
            rect(-100.0, 100.0, -100.0, 100.0),
            rect(-90.0, 90.0, -90.0, 90.0),
        ),
        (
            1,
            rect(30.0, 50.0, -20.0, 20.0),
            rect(25.0, 55.0, -25.0, 25.0),
        ),
    ]
}

fn app_fence(zones: &[Zone]) -> AppGeofence {
    AppGeofence::new(
        1,
        zones
            .iter()
            .map(|(k, c, s)| (*k, c.as_slice(), s.as_slice())),
    )
    .unwrap()
}

impl Harness {
    /// GEOFENCE_SET_DATA as the gateway publishes it.
    fn fence(&mut self, zones: &[Zone]) -> Outputs {
        let g = app_fence(zones);
        self.engine.handle_app_geofence(&g, self.now);
        self.drain()
    }

    fn update(&mut self, action: u8, polygon: u16, vertex: u16, p: [f64; 2]) -> Outputs {
        self.app(ShotRequest::GeofenceUpdatePoly {
            action,
            polygon_index: polygon,
            vertex_index: vertex,
            lat_deg: p[0],
            lon_deg: p[1],
            sub_lat_deg: p[0],
            sub_lon_deg: p[1],
        })
    }

    /// The vehicle `north_m` north of the start, flying north at `speed`.
    fn place(&mut self, north_m: f64, speed: f32) {
        self.state.lat_deg = LAT + north_m * M_LAT;
        self.state.lon_deg = LON;
        self.state.vel_ned_mps = [speed, 0.0, 0.0];
        self.push_state();
    }
}

fn ack(count: u16, valid: bool) -> ShotEvent {
    ShotEvent::GeofenceSetAck { count, valid }
}

fn error_text(out: &Outputs) -> String {
    out.to_app
        .iter()
        .find_map(|m| match m {
            ShotEvent::Error(t) => Some(t.clone()),
            _ => None,
        })
        .unwrap_or_default()
}

fn north_of(p: &[f64; 2]) -> f64 {
    (p[0] - LAT) / M_LAT
}

#[test]
fn a_valid_geofence_is_acknowledged_and_given_to_the_arbiter() {
    let mut h = Harness::ready();
    let out = h.fence(&field());
    assert_eq!(out.to_app, [ack(2, true)]);
    let set: GeofenceSet = out.geofence.expect("published");
    assert_eq!(set.vehicle_id, VEHICLE);
    assert_eq!(set.enabled, 1);
    assert_eq!(set.source, CommandSource::ShotEngine.to_wire());
    assert_eq!((set.ceiling_m, set.floor_m), (10_000.0, -1_000.0));
    let polygons = set.polygons().expect("the arbiter accepts it");
    assert_eq!(polygons.len(), 2);
    // The fence polygons, not the hold lines.
    assert_eq!(polygons[0], (FenceKind::KeepIn, &field()[0].1[..]));
    assert_eq!(polygons[1], (FenceKind::KeepOut, &field()[1].1[..]));
    assert_eq!(
        h.stats.gauge("skymesh_shot_geofence_polygons", &[]).get(),
        2.0
    );
    assert!(out.commands.is_empty(), "the vehicle is well inside");
    assert!(h.run(200).to_app.is_empty());
}

#[test]
fn an_invalid_geofence_is_refused_and_the_one_before_kept() {
    let mut h = Harness::ready();
    h.fence(&field()[..1]);
    let good = field()[1].clone();
    let mut nan = good.clone();
    nan.2[1][0] = f64::NAN;
    let mut crossed = good.clone();
    crossed.1.swap(1, 2);
    let cases = [
        (
            (1u8, good.1[..2].to_vec(), good.2[..2].to_vec()),
            "2 vertices",
        ),
        (
            (1, good.1.clone(), good.2[..3].to_vec()),
            "4 polygon vertices but 3",
        ),
        ((2, good.1.clone(), good.2.clone()), "type 2"),
        (nan, "not a finite"),
        (crossed, "crosses itself"),
    ];
    for (zone, why) in cases {
        let out = h.fence(&[field()[0].clone(), zone]);
        assert_eq!(out.to_app[0], ack(1, false), "{why}");
        let text = error_text(&out);
        assert!(
            text.contains("polygon 1") && text.contains(why),
            "{why}: {text}"
        );
        assert!(
            text.contains("the previous 1-polygon geofence stays"),
            "{text}"
        );
        assert!(out.geofence.is_none(), "{why}: nothing for the arbiter");
    }
    // More than the arbiter carries (no `AppGeofence` can hold it; the engine
    // checks all the same).
    let long: Vec<[f64; 2]> = (0..33).map(|i| pt(f64::from(i), 0.0)).collect();
    for (coord, sub, kinds) in [
        (
            vec![good.1.clone(); 9],
            vec![good.2.clone(); 9],
            vec![1u8; 9],
        ),
        (vec![long.clone()], vec![long.clone()], vec![1u8]),
    ] {
        let zones: Vec<_> = kinds
            .iter()
            .zip(coord.iter().zip(&sub))
            .map(|(k, (c, s))| (*k, c.as_slice(), s.as_slice()))
            .collect();
        h.engine.geofence_set(&zones);
        let out = h.drain();
        assert_eq!(out.to_app[0], ack(1, false));
        assert!(error_text(&out).contains("at most"), "{}", error_text(&out));
    }
    // With no fence before: the ack says 0.
    let mut h = Harness::ready();
    let out = h.fence(&[(0, rect(0.0, 1.0, 0.0, 1.0)[..2].to_vec(), vec![])]);
    assert_eq!(out.to_app[0], ack(0, false));
    assert!(error_text(&out).contains("no geofence is set"));
}

#[test]
fn no_polygon_is_an_empty_fence() {
    let mut h = Harness::ready();
    let out = h.fence(&[]);
    assert_eq!(out.to_app, [ack(0, true)]);
    assert!(out.geofence.is_none(), "nothing was set, nothing to clear");
    h.fence(&field());
    let out = h.fence(&[]);
    assert_eq!(out.to_app, [ack(0, true)]);
    assert_eq!(out.geofence.unwrap().enabled, 0);
}

#[test]
fn update_poly_updates_adds_and_removes_vertices() {
    let mut h = Harness::ready();
    // No fence yet.
    let out = h.update(0, 0, 0, pt(0.0, 0.0));
    assert_eq!(out.to_app[0], ack(0, false));
    assert!(error_text(&out).contains("no geofence is set"));

    h.fence(&field());
    // Update: the keep-out's first corner moves 5 m south.
    let out = h.update(0, 1, 0, pt(25.0, -20.0));
    assert_eq!(out.to_app, [ack(2, true)]);
    let set = out.geofence.unwrap();
    assert_eq!(set.polygons().unwrap()[1].1[0], pt(25.0, -20.0));
    // Add: a fifth vertex, appended.
    let out = h.update(1, 1, 4, pt(40.0, -25.0));
    assert_eq!(out.to_app, [ack(2, true)]);
    assert_eq!(out.geofence.unwrap().polygons[1].vertex_count, 5);
    // Remove it again, then one more: a triangle is still a polygon.
    for n in [4, 3] {
        let out = h.update(2, 1, 0, [0.0, 0.0]);
        assert_eq!(out.to_app, [ack(2, true)]);
        assert_eq!(out.geofence.unwrap().polygons[1].vertex_count, n);
    }
    // Two vertices are not.
    let out = h.update(2, 1, 0, [0.0, 0.0]);
    assert_eq!(out.to_app[0], ack(2, false));
    assert!(out.geofence.is_none());
    // Bad indices and a made-up action (the codec allows 0..=2; the engine checks too).
    for (action, polygon, vertex, why) in [
        (0, 2, 0, "polygon 2 does not exist"),
        (0, 1, 3, "polygon 1 has no vertex 3"),
        (1, 1, 4, "polygon 1 has no vertex 4"),
    ] {
        let out = h.update(action, polygon, vertex, pt(40.0, 0.0));
        assert_eq!(out.to_app[0], ack(2, false), "{why}");
        assert!(error_text(&out).contains(why), "{}", error_text(&out));
    }
    h.engine.geofence_update(7, 0, 0, LAT, LON, LAT, LON);
    assert!(error_text(&h.drain()).contains("unknown update action 7"));
}

#[test]
fn clear_from_the_app_is_acknowledged_and_given_to_the_arbiter() {
    let mut h = Harness::ready();
    let out = h.app(ShotRequest::GeofenceClear);
    assert_eq!(out.to_app, [ack(0, true)]);
    assert!(out.geofence.is_none(), "ours was never set");
    h.fence(&field());
    let out = h.app(ShotRequest::GeofenceClear);
    assert_eq!(out.to_app, [ack(0, true)]);
    let set = out.geofence.unwrap();
    assert_eq!((set.enabled, set.polygon_count), (0, 0));
    assert_eq!(set.source, CommandSource::ShotEngine.to_wire());
}

#[test]
fn the_app_is_answered_only_by_the_arbiters_decision() {
    let mut h = Harness::ready();
    h.fence_answer = FenceAnswer::Silent;
    let out = h.fence(&field());
    let set = out.geofence.expect("given to the arbiter");
    assert_ne!(set.request_id, 0);
    assert!(out.to_app.is_empty(), "no answer before the arbiter's");
    // Another source's decision, and a decision on another request: no answer.
    let mut ev = ArbiterEvent {
        vehicle_id: VEHICLE,
        kind: ArbiterEventKind::GeofenceUpdated.to_wire(),
        source: CommandSource::SwarmQueue.to_wire(),
        request_id: set.request_id,
        ..ArbiterEvent::default()
    };
    h.engine.handle_arbiter_event(&ev, h.now);
    ev.source = CommandSource::ShotEngine.to_wire();
    ev.request_id = set.request_id + 1;
    h.engine.handle_arbiter_event(&ev, h.now);
    assert!(h.drain().to_app.is_empty());
    ev.request_id = set.request_id;
    h.engine.handle_arbiter_event(&ev, h.now);
    assert_eq!(h.drain().to_app, [ack(2, true)]);
    // Each change has its own request id.
    h.fence_answer = FenceAnswer::Take;
    let next = h.fence(&field()[..1]).geofence.unwrap();
    assert!(next.request_id != set.request_id && next.request_id != 0);
}

#[test]
fn a_fence_the_arbiter_refuses_is_answered_invalid_and_the_one_before_kept() {
    let mut h = Harness::ready();
    h.fence(&field()[..1]);
    h.fence_answer = FenceAnswer::Refuse;
    let out = h.fence(&field());
    assert!(out.geofence.is_some(), "the engine found it valid");
    assert_eq!(out.to_app[0], ack(1, false));
    let text = error_text(&out);
    assert!(
        text.contains("the vehicle refused it: polygon 0 crosses itself"),
        "{text}"
    );
    assert!(
        text.contains("the previous 1-polygon geofence stays"),
        "{text}"
    );
    assert_eq!(
        h.stats.gauge("skymesh_shot_geofence_polygons", &[]).get(),
        1.0
    );
    // The engine's own check is back on the fence the arbiter keeps: editing the
    // keep-out (polygon 1) finds none.
    h.fence_answer = FenceAnswer::Take;
    let out = h.update(0, 1, 0, pt(25.0, -20.0));
    assert_eq!(out.to_app[0], ack(1, false));
    assert!(error_text(&out).contains("polygon 1 does not exist"));
    // A refused clear: the fence stays.
    h.fence_answer = FenceAnswer::Refuse;
    let out = h.app(ShotRequest::GeofenceClear);
    assert_eq!(out.to_app[0], ack(1, false));
}

#[test]
fn no_decision_from_the_arbiter_is_answered_invalid_after_two_seconds() {
    let mut h = Harness::ready();
    // On the ground: the engine sleeps between its time-driven jobs.
    h.status.armed = 0;
    h.push_status();
    h.tick();
    assert!(h.engine.idle_until().is_some());
    h.fence_answer = FenceAnswer::Silent;
    assert!(h.fence(&field()).to_app.is_empty());
    assert!(h.engine.idle_until().is_none(), "ticks for the timeout");
    let early = h.run(1_800);
    assert!(early.to_app.is_empty(), "{:?}", early.to_app);
    let late = h.run(400);
    assert_eq!(late.to_app[0], ack(0, false));
    assert!(
        error_text(&late).contains("did not answer"),
        "{}",
        error_text(&late)
    );
    assert!(h.engine.idle_until().is_some(), "nothing waits any more");
}

#[test]
fn the_app_leaving_clears_only_the_engines_own_fence() {
    let mut h = Harness::ready();
    h.fence(&field());
    let out = h.session(1, false);
    let set = out.geofence.expect("a clear for the arbiter");
    assert_eq!((set.enabled, set.polygon_count), (0, 0));
    assert_eq!(set.source, CommandSource::ShotEngine.to_wire());
    assert_eq!(
        set.target_source,
        skymesh_ipc_types::NO_HOLDER,
        "its own only"
    );
    assert_ne!(set.request_id, 0);
    assert!(out.to_app.is_empty());
}

#[test]
fn the_fence_goes_with_the_app_and_the_next_app_is_told() {
    let mut h = Harness::ready();
    h.fence(&field());
    let out = h.session(1, false);
    assert_eq!(out.geofence.unwrap().enabled, 0);
    assert!(out.to_app.is_empty(), "nobody to tell");
    let out = h.connect_app(2);
    assert!(
        out.to_app.contains(&ShotEvent::GeofenceClear),
        "{:?}",
        out.to_app
    );
    // Once.
    h.session(2, false);
    assert!(!h.connect_app(3).to_app.contains(&ShotEvent::GeofenceClear));
}

#[test]
fn a_pilot_flying_at_a_keep_out_is_held_at_its_hold_line_then_handed_back() {
    let mut h = Harness::ready();
    h.fence(&field());
    // 5 m/s at 20 m north: 8.3 m to stop + 2.5 m of latency reaches 30.8 m.
    h.place(10.0, 5.0);
    assert!(h.tick().commands.is_empty(), "10 m north: clear");
    h.place(20.0, 5.0);
    let out = h.tick();
    assert_eq!(out.to_app, [ShotEvent::GeofenceActivated]);
    let sent = cmds(&out);
    assert_eq!(sent[0], Command::GrabFlightAuthority);
    assert_eq!(sent[1], Command::SetMode(FlightMode::Guided));
    let Command::GoTo {
        lat_deg,
        lon_deg,
        alt_rel_m,
        speed_mps,
        ..
    } = sent[2]
    else {
        panic!("{sent:?}");
    };
    // On the keep-out's hold line, south of it, at the vehicle's altitude.
    assert!(
        (north_of(&[lat_deg, lon_deg]) - 25.0).abs() < 0.1,
        "{}",
        north_of(&[lat_deg, lon_deg])
    );
    assert!((lon_deg - LON).abs() * 1e5 < 1.0);
    assert_eq!(alt_rel_m, ALT);
    assert_eq!(speed_mps, Some(6.0));
    assert_eq!(sent.len(), 3);
    assert!(all_ours(&out));
    assert_eq!(h.counter("skymesh_shot_geofence_activations_total", &[]), 1);

    // Still on its way: nothing more (no second activation while holding).
    h.set_mode(FlightMode::Guided);
    h.place(27.0, -1.0);
    let out = h.run(2_000);
    assert!(out.to_app.is_empty());
    assert!(kinds(&out)
        .iter()
        .all(|k| *k == CommandKind::GrabFlightAuthority));
    // At the hold point and still: LOITER, authority back.
    h.place(25.2, 0.1);
    let out = h.tick();
    assert_eq!(
        cmds(&out),
        [
            Command::SetMode(FlightMode::Loiter),
            Command::ReleaseFlightAuthority
        ]
    );
    h.set_mode(FlightMode::Loiter);
    assert!(h.run(500).commands.is_empty());

    // The pilot pushes out again: held again.
    h.place(25.2, 4.0);
    let out = h.tick();
    assert_eq!(out.to_app, [ShotEvent::GeofenceActivated]);
    assert_eq!(h.counter("skymesh_shot_geofence_activations_total", &[]), 2);
}

#[test]
fn leaving_the_keep_in_area_is_held_inside_its_hold_line() {
    let mut h = Harness::ready();
    h.fence(&field()[..1]);
    h.place(-95.0, -4.0);
    let out = h.tick();
    assert_eq!(out.to_app, [ShotEvent::GeofenceActivated]);
    let Some(Command::GoTo { lat_deg, .. }) = cmds(&out).into_iter().nth(2) else {
        panic!("{:?}", cmds(&out));
    };
    // The first point outside is on the fence (−100 m): held at −90 m.
    assert!((north_of(&[lat_deg, LON]) + 90.0).abs() < 0.1);
}

#[test]
fn a_shot_flying_at_the_fence_ends_with_the_reason_geofence() {
    let mut h = Harness::ready();
    h.orbiting();
    h.fence(&field());
    h.tick();
    h.place(20.0, 6.0);
    let out = h.tick();
    assert_eq!(
        out.to_app,
        [ShotEvent::CurrentShot(NONE), ShotEvent::GeofenceActivated]
    );
    assert_eq!(h.engine.current_shot(), NONE);
    assert_eq!(h.engine.last_exit(), "geofence");
    assert_eq!(
        h.counter("skymesh_shot_exits_total", &[("reason", "geofence")]),
        1
    );
    // The shot's ROI cleared and authority handed to the hold, which asks for GUIDED
    // again: the status saying GUIDED may predate a LOITER no heartbeat showed yet.
    assert_eq!(
        kinds(&out),
        [
            CommandKind::ClearRoi,
            CommandKind::ReleaseFlightAuthority,
            CommandKind::GrabFlightAuthority,
            CommandKind::SetMode,
            CommandKind::GoTo
        ]
    );
    assert!(!h.engine.is_flying());
    // A new shot may start; it takes the vehicle over from the hold.
    h.app(ShotRequest::StartShot(ORBIT));
    h.app(ShotRequest::Location(loc(-30.0)));
    h.place(20.0, 0.0);
    h.tick();
    assert!(!h.engine.fence.holding());
    assert!(h.engine.is_flying());
}

#[test]
fn no_check_on_the_ground_in_autonomous_modes_or_without_position() {
    let setups: [fn(&mut Harness); 6] = [
        |h: &mut Harness| h.status.armed = 0,
        |h: &mut Harness| h.state.alt_rel_m = 0.5,
        |h: &mut Harness| h.status.mode = FlightMode::Rtl.to_wire(),
        |h: &mut Harness| h.status.mode = FlightMode::Auto.to_wire(),
        // GUIDED by someone else (no shot of ours).
        |h: &mut Harness| h.status.mode = FlightMode::Guided.to_wire(),
        |h: &mut Harness| h.state.position_valid = 0,
    ];
    for setup in setups {
        let mut h = Harness::ready();
        h.fence(&field());
        setup(&mut h);
        h.push_status();
        h.place(28.0, 8.0);
        let out = h.run(400);
        assert!(out.commands.is_empty() && out.to_app.is_empty(), "{out:?}");
    }
}

#[test]
fn a_refused_hold_point_brakes_where_the_vehicle_is() {
    let mut h = Harness::ready();
    h.fence(&field());
    h.place(20.0, 5.0);
    let out = h.tick();
    let goto = find(&out, CommandKind::GoTo).unwrap();
    let out = h.ack(&goto, AckResult::Refused, RefusalReason::Geofence);
    assert_eq!(cmds(&out), [Command::Brake]);
    h.set_mode(FlightMode::Guided);
    h.place(24.0, 0.2);
    assert_eq!(
        cmds(&h.tick()),
        [
            Command::SetMode(FlightMode::Loiter),
            Command::ReleaseFlightAuthority
        ]
    );
}

#[test]
fn a_hold_the_arbiter_or_the_autopilot_refuses_is_given_up_and_told() {
    // Authority refused: the pilot (manual RC) outranks the engine.
    let mut h = Harness::ready();
    h.fence(&field());
    h.place(20.0, 5.0);
    let out = h.tick();
    let grab = find(&out, CommandKind::GrabFlightAuthority).unwrap();
    let out = h.ack(&grab, AckResult::Refused, RefusalReason::NoAuthority);
    assert!(error_text(&out).starts_with("geofence: could not hold the vehicle (no_authority"));
    assert!(!h.engine.fence.holding());
    assert!(out.commands.is_empty());

    // GUIDED never comes.
    let mut h = Harness::ready();
    h.fence(&field());
    h.place(20.0, 5.0);
    h.tick();
    h.place(20.0, 0.0);
    let out = h.run(6_000);
    assert!(error_text(&out).contains("no GUIDED"), "{out:?}");
    assert!(!h.engine.fence.holding());
    assert!(!kinds(&out).contains(&CommandKind::SetMode));
}

#[test]
fn the_pilot_changing_the_mode_during_a_hold_takes_the_vehicle() {
    let mut h = Harness::ready();
    h.fence(&field());
    h.place(20.0, 5.0);
    h.tick();
    h.set_mode(FlightMode::Guided);
    h.tick();
    h.set_mode(FlightMode::AltHold);
    // Moving away: no re-activation, nothing sent.
    h.place(22.0, -2.0);
    let out = h.tick();
    assert!(out.commands.is_empty() && out.to_app.is_empty());
    assert!(!h.engine.fence.holding());
}

/// Only a heartbeat from after the hold asked for GUIDED counts: autopilot-link's
/// once-a-second status repeating an older GUIDED is not the hold's, and a mode
/// after it is not the pilot taking over.
#[test]
fn a_heartbeat_from_before_the_holds_request_is_not_its_guided() {
    let mut h = Harness::ready();
    h.fence(&field());
    h.place(20.0, 5.0);
    h.tick();
    assert!(h.engine.fence.holding());
    h.now += 200 * MS;
    h.status.mode = FlightMode::Guided.to_wire();
    h.status.heartbeat_age_ms = 900;
    h.push_status();
    h.tick();
    h.status.heartbeat_age_ms = 0;
    h.set_mode(FlightMode::AltHold);
    h.tick();
    assert!(
        h.engine.fence.holding(),
        "the repeated GUIDED was taken for the hold's"
    );
    // No GUIDED from after the request within the timeout: given up, and said so
    // (the pilot flying away meanwhile: no new hold).
    h.place(22.0, -2.0);
    let out = h.run(6_000);
    assert!(!h.engine.fence.holding());
    assert!(error_text(&out).contains("no GUIDED"), "{out:?}");
}

#[test]
fn clearing_the_fence_or_stopping_during_a_hold_hands_back_in_loiter() {
    let mut h = Harness::ready();
    h.fence(&field());
    h.place(20.0, 5.0);
    h.tick();
    let out = h.app(ShotRequest::GeofenceClear);
    assert_eq!(
        cmds(&out),
        [
            Command::SetMode(FlightMode::Loiter),
            Command::ReleaseFlightAuthority
        ]
    );
    assert_eq!(out.to_app, [ack(0, true)]);

    let mut h = Harness::ready();
    h.fence(&field());
    h.place(20.0, 5.0);
    h.tick();
    let out = h.engine.shutdown(h.now);
    assert_eq!(
        cmds(&out),
        [
            Command::SetMode(FlightMode::Loiter),
            Command::ReleaseFlightAuthority
        ]
    );
    assert!(out.geofence.is_none(), "the fence stays with the arbiter");
}
