//! `Engine::idle_until`: when the service loop may skip its `loop_hz` ticks.

use super::*;
use crate::engine::STATUS_PERIOD_NS;

#[test]
fn an_idle_engine_on_the_ground_waits_for_its_status_period() {
    let mut h = Harness::new();
    h.vehicle_ok();
    h.status.armed = 0;
    h.push_status();
    // The first status is due at once.
    assert_eq!(h.engine.idle_until(), Some(0));
    assert!(h.drain().status.is_some());
    assert_eq!(h.engine.idle_until(), Some(h.now + STATUS_PERIOD_NS));
}

#[test]
fn a_connected_app_adds_its_session_timeout() {
    let mut h = Harness::new();
    h.drain();
    h.connect_app(1);
    let heard = h.now;
    // Long after the status period: the status is what is due first.
    assert_eq!(h.engine.idle_until(), Some(heard + STATUS_PERIOD_NS));
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
