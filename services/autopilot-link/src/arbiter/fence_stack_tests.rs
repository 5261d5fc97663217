//! Tests of the fence stack: one fence per source, who may clear whose, the
//! combined altitudes, invalid samples; the helpers the stopping tests share.

use skymesh_ipc_types::{
    AckResult, ArbiterEventKind, Command, CommandSource,
    CommandSource::{Operator, Safety, ShotEngine, SwarmQueue, Vision},
    FenceKind, GeofenceSet, RefusalReason, NO_HOLDER,
};

use super::geofence::LocalFrame;
use super::tests::{flying, refusal, sample, settings, S};
use super::{Arbiter, Effect};

const HOME: (f64, f64) = (-35.363261, 149.165230);

/// Latitude/longitude of a point `north`/`east` metres from home.
pub(super) fn ll(north: f64, east: f64) -> [f64; 2] {
    let unit = LocalFrame::new(HOME.0, HOME.1).to_local(HOME.0 + 1e-3, HOME.1 + 1e-3);
    [
        HOME.0 + north / unit.x * 1e-3,
        HOME.1 + east / unit.y * 1e-3,
    ]
}

/// `source`'s keep-in rectangle, north `n0..n1`, east `e0..e1` metres.
pub(super) fn keep_in(
    source: CommandSource,
    (n0, n1): (f64, f64),
    (e0, e1): (f64, f64),
) -> GeofenceSet {
    let mut set = GeofenceSet {
        vehicle_id: 1,
        enabled: 1,
        source: source.to_wire(),
        request_id: 40 + u32::from(source.to_wire()),
        ceiling_m: 60.0,
        floor_m: -5.0,
        ..Default::default()
    };
    assert!(set.push_polygon(
        FenceKind::KeepIn,
        &[ll(n0, e0), ll(n1, e0), ll(n1, e1), ll(n0, e1)]
    ));
    set
}

pub(super) fn clear(
    source: CommandSource,
    target: Option<CommandSource>,
    request_id: u32,
) -> GeofenceSet {
    GeofenceSet {
        vehicle_id: 1,
        enabled: 0,
        source: source.to_wire(),
        target_source: target.map_or(NO_HOLDER, CommandSource::to_wire),
        request_id,
        ..Default::default()
    }
}

/// The one decision event: (kind, request id, detail).
fn decision(fx: &[Effect]) -> (ArbiterEventKind, u32, &str) {
    match fx {
        [Effect::Fence {
            kind,
            request_id,
            detail,
            ..
        }] => (*kind, *request_id, detail.as_str()),
        other => panic!("expected one fence decision, got {other:?}"),
    }
}

fn goto(north: f64, east: f64) -> Command {
    let [lat_deg, lon_deg] = ll(north, east);
    Command::GoTo {
        lat_deg,
        lon_deg,
        alt_rel_m: 10.0,
        yaw_deg: None,
        speed_mps: Some(3.0),
    }
}

#[test]
fn each_source_keeps_its_own_fence_and_clears_only_its_own() {
    let mut a = Arbiter::new(settings());
    // GroundControl (the swarm queue) sets a 100 m box, the Solo app (the shot
    // engine) a fence that reaches further east but not as far north.
    let fx = a.set_geofence(&keep_in(SwarmQueue, (-50.0, 50.0), (-50.0, 50.0)), 1);
    assert_eq!(decision(&fx).0, ArbiterEventKind::GeofenceUpdated);
    assert_eq!(decision(&fx).1, 44, "request id echoed");
    let fx = a.set_geofence(&keep_in(ShotEngine, (-30.0, 30.0), (-30.0, 200.0)), 1);
    assert_eq!(decision(&fx).0, ArbiterEventKind::GeofenceUpdated);
    assert_eq!(a.fence().len(), 2);
    assert!(a.fence().contains(ll(20.0, 20.0)[0], ll(20.0, 20.0)[1]));
    let [lat, lon] = ll(40.0, 0.0);
    assert!(!a.fence().contains(lat, lon), "outside the Solo fence");
    let [lat, lon] = ll(0.0, 80.0);
    assert!(
        !a.fence().contains(lat, lon),
        "outside the GroundControl box"
    );
    let v = flying(0.0, 0.0, [0.0; 3]);
    let d = a.decide(S, &sample(Operator, goto(0.0, 80.0), S), &v);
    assert_eq!(refusal(&d).0, RefusalReason::Geofence, "the box holds");
    let d = a.decide(S, &sample(Operator, goto(40.0, 0.0), S), &v);
    assert_eq!(
        refusal(&d).0,
        RefusalReason::Geofence,
        "the Solo fence holds"
    );

    // The shot engine may not clear the swarm queue's box...
    let fx = a.set_geofence(&clear(ShotEngine, Some(SwarmQueue), 7), 1);
    assert_eq!(
        decision(&fx),
        (
            ArbiterEventKind::GeofenceInvalid,
            7,
            "shot_engine may not clear swarm_queue's fence"
        )
    );
    assert_eq!(a.fence().len(), 2);
    // ... nor set a fence in its name.
    let mut theirs = keep_in(ShotEngine, (-5.0, 5.0), (-5.0, 5.0));
    theirs.target_source = SwarmQueue.to_wire();
    let fx = a.set_geofence(&theirs, 1);
    assert_eq!(decision(&fx).0, ArbiterEventKind::GeofenceInvalid);
    // The app disconnects: its gateway clears the Solo fence; the box still holds.
    let fx = a.set_geofence(&clear(ShotEngine, None, 8), 1);
    assert_eq!(
        decision(&fx),
        (
            ArbiterEventKind::GeofenceUpdated,
            8,
            "shot_engine cleared its fence; 1 left"
        )
    );
    assert!(a.fence().get(ShotEngine).is_none());
    assert!(a.fence().get(SwarmQueue).is_some());
    let d = a.decide(2 * S, &sample(Operator, goto(40.0, 0.0), 2 * S), &v);
    assert_ne!(d.result(), AckResult::Refused, "inside the box now: {d:?}");
    let d = a.decide(2 * S, &sample(Operator, goto(0.0, 80.0), 2 * S), &v);
    assert_eq!(
        refusal(&d).0,
        RefusalReason::Geofence,
        "the box still holds"
    );
    // A second clear of a fence that is gone: accepted, nothing changes.
    let fx = a.set_geofence(&clear(ShotEngine, None, 9), 1);
    assert_eq!(decision(&fx).0, ArbiterEventKind::GeofenceUpdated);
    assert_eq!(a.fence().len(), 1);
}

#[test]
fn safety_and_operator_may_clear_any_fence_and_are_named() {
    let mut a = Arbiter::new(settings());
    a.set_geofence(&keep_in(SwarmQueue, (-50.0, 50.0), (-50.0, 50.0)), 1);
    a.set_geofence(&keep_in(Vision, (-40.0, 40.0), (-40.0, 40.0)), 1);
    let fx = a.set_geofence(&clear(Operator, Some(SwarmQueue), 3), 1);
    assert_eq!(
        decision(&fx),
        (
            ArbiterEventKind::GeofenceUpdated,
            3,
            "operator cleared swarm_queue's fence; 1 left"
        )
    );
    let fx = a.set_geofence(&clear(Safety, Some(Vision), 4), 1);
    assert_eq!(decision(&fx).2, "safety cleared vision's fence; 0 left");
    assert!(a.fence().is_empty());
    assert_eq!(a.fence().ceiling_m(), None);
}

#[test]
fn the_fences_combine_to_the_strictest_altitudes_and_restore_from_their_samples() {
    let mut a = Arbiter::new(settings());
    let mut box_set = keep_in(SwarmQueue, (-50.0, 50.0), (-50.0, 50.0));
    box_set.ceiling_m = 40.0;
    box_set.floor_m = -10.0;
    let mut solo = keep_in(ShotEngine, (-30.0, 30.0), (-30.0, 200.0));
    solo.ceiling_m = 80.0;
    solo.floor_m = 2.0;
    a.set_geofence(&solo, 1);
    a.set_geofence(&box_set, 1);
    assert_eq!(a.fence().ceiling_m(), Some(40.0));
    assert_eq!(a.fence().floor_m(), Some(2.0));
    assert!(a.fence().altitude_ok(20.0));
    assert!(!a.fence().altitude_ok(45.0) && !a.fence().altitude_ok(1.0));
    // The state file keeps the samples; set again, they give the same stack.
    let sets = a.fence_sets();
    assert_eq!(sets, [solo, box_set], "ordered by source");
    let mut b = Arbiter::new(settings());
    for set in &sets {
        assert_eq!(
            decision(&b.set_geofence(set, 1)).0,
            ArbiterEventKind::GeofenceUpdated
        );
    }
    assert_eq!(b.fence(), a.fence());
    // A source's new fence replaces only its own.
    a.set_geofence(&keep_in(ShotEngine, (-20.0, 20.0), (-20.0, 20.0)), 1);
    assert_eq!(a.fence().len(), 2);
    assert_eq!(a.fence().floor_m(), Some(-5.0));
}

#[test]
fn invalid_samples_change_nothing_and_say_why() {
    let mut a = Arbiter::new(settings());
    a.set_geofence(&keep_in(SwarmQueue, (-50.0, 50.0), (-50.0, 50.0)), 1);
    let mut bad = keep_in(SwarmQueue, (-10.0, 10.0), (-10.0, 10.0));
    bad.polygons[0].vertices[1][0] = f64::NAN;
    let fx = a.set_geofence(&bad, 1);
    assert_eq!(decision(&fx).0, ArbiterEventKind::GeofenceInvalid);
    assert_eq!(decision(&fx).1, 44);
    let fx = a.set_geofence(&keep_in(SwarmQueue, (-1.0, 1.0), (-1.0, 1.0)), 2);
    assert_eq!(
        decision(&fx),
        (ArbiterEventKind::GeofenceInvalid, 44, "fence for vehicle 1")
    );
    let mut unknown = keep_in(SwarmQueue, (-1.0, 1.0), (-1.0, 1.0));
    unknown.source = 99;
    assert_eq!(
        decision(&a.set_geofence(&unknown, 1)).2,
        "unknown source 99"
    );
    let mut target = clear(Operator, None, 5);
    target.target_source = 77;
    assert_eq!(
        decision(&a.set_geofence(&target, 1)).2,
        "unknown target source 77"
    );
    let fx = a.fence_sets();
    assert_eq!(fx.len(), 1);
    assert_eq!(fx[0], keep_in(SwarmQueue, (-50.0, 50.0), (-50.0, 50.0)));
}
