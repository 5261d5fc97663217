//! `Engine::idle_until`: when the service loop may skip its `loop_hz` ticks.

use super::*;
use skymesh_ipc_types::shot_api::shots::ORBIT;
use skymesh_ipc_types::shot_api::ShotRequest;

use crate::engine::{IDLE_STATUS_PERIOD_NS, STATUS_PERIOD_NS};

#[test]
fn an_idle_engine_on_the_ground_waits_for_its_status_period() {
    let mut h = Harness::new();
    h.vehicle_ok();
    h.status.armed = 0;
    h.push_status();
    // The first status is due at once.
    assert_eq!(h.engine.idle_until(), Some(0));
    assert!(h.drain().status.is_some());
    // No shot: the next one at the first whole second at least a second later.
    assert_eq!(h.now, 1_000 * MS);
    assert_eq!(h.engine.idle_until(), Some(2_000 * MS));
}

#[test]
fn an_idle_status_comes_once_a_second_on_the_whole_second_and_at_once_on_a_change() {
    let mut h = Harness::new();
    h.vehicle_ok();
    h.status.armed = 0;
    h.push_status();
    h.now = 1_300 * MS;
    assert!(h.drain().status.is_some());
    // Due at the first whole second ≥ 2.3 s, not 200 ms later as during a shot.
    assert_eq!(h.engine.idle_until(), Some(3_000 * MS));
    for at in [1_500, 2_300, 2_999] {
        h.now = at * MS;
        assert!(h.drain().status.is_none(), "no status at {at} ms");
    }
    h.now = 3_000 * MS;
    assert!(h.drain().status.is_some());
    assert_eq!(
        h.engine.idle_until(),
        Some(3_000 * MS + IDLE_STATUS_PERIOD_NS)
    );
    // A change is published at once, off the grid.
    h.now = 3_100 * MS;
    let out = h.connect_app(1);
    assert!(out.status.is_some_and(|s| s.app_connected == 1));
}

#[test]
fn during_a_shot_the_status_comes_five_times_a_second() {
    let mut h = Harness::ready();
    assert!(h.app(ShotRequest::StartShot(ORBIT)).status.is_some());
    assert_eq!(h.engine.idle_until(), None);
    let first = h.now;
    h.now = first + STATUS_PERIOD_NS - 1;
    assert!(h.drain().status.is_none());
    h.now = first + STATUS_PERIOD_NS;
    assert!(h.drain().status.is_some());
}

#[test]
fn a_connected_app_adds_its_session_timeout() {
    let mut h = Harness::new();
    h.drain();
    h.connect_app(1);
    let heard = h.now;
    // The status (a second later, on the whole second) is what is due first.
    assert_eq!(heard % IDLE_STATUS_PERIOD_NS, 0);
    assert_eq!(h.engine.idle_until(), Some(heard + IDLE_STATUS_PERIOD_NS));
    // Statuses published since: the session timeout (3 s) comes first, and a tick
    // then ends the session as the periodic tick did.
    h.now = heard + 2_900 * MS;
    h.drain();
    let timeout = heard + 3_000 * MS + 1;
    assert_eq!(h.engine.idle_until(), Some(timeout));
    h.now = timeout;
    let out = h.engine.tick(h.now);
    assert!(out.status.is_some_and(|s| s.app_connected == 0));
}

#[test]
fn an_armed_vehicle_needs_every_tick() {
    let mut h = Harness::new();
    h.vehicle_ok();
    assert_eq!(h.engine.idle_until(), None);
    // Disarmed: the breadcrumbs recorded while armed are cleared by one tick, then idle.
    h.run(200);
    h.status.armed = 0;
    h.push_status();
    assert_eq!(h.engine.idle_until(), None);
    h.tick();
    assert!(h.engine.idle_until().is_some());
}
