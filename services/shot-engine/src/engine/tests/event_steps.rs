//! Which inputs ask the service for a step at once (`take_step_request`).

use skymesh_ipc_types::shot_api::{shots, ShotRequest};
use skymesh_ipc_types::Button;

use super::*;

#[test]
fn guidance_changes_of_a_flying_shot_ask_for_a_step() {
    let mut h = Harness::ready();
    h.connect_app(1);
    h.app(ShotRequest::StartShot(shots::ORBIT));
    // In setup (no ROI yet): nothing flies, nothing to step.
    assert!(!h.engine.take_step_request());
    // The ROI starts the flight: the first setpoint should not wait for a tick.
    h.app(ShotRequest::Location(loc(30.0)));
    assert!(h.engine.take_step_request());
    assert!(!h.engine.take_step_request(), "asked once");
    h.set_mode(FlightMode::Guided);
    h.run(200);

    h.app(ShotRequest::ShotOptions { cruise_speed: 3.0 });
    assert!(h.engine.take_step_request());
    h.button(Button::Pause);
    assert!(h.engine.take_step_request());
    // A tick is the step: a request made before it is served by it.
    h.app(ShotRequest::ShotOptions { cruise_speed: 1.0 });
    h.tick();
    assert!(!h.engine.take_step_request());
}

#[test]
fn other_messages_and_idle_engines_do_not() {
    let mut h = Harness::ready();
    h.connect_app(1);
    h.app(ShotRequest::ShotOptions { cruise_speed: 3.0 });
    assert!(!h.engine.take_step_request(), "no shot");
    h.orbiting();
    h.run(200);
    h.app(ShotRequest::GoProRequestState);
    assert!(!h.engine.take_step_request(), "not guidance");
    // Follow-stream fixes are a stream of their own: stepped by the loop.
    h.fix(5.0);
    assert!(!h.engine.take_step_request());
    h.app(ShotRequest::StartShot(shots::NONE));
    assert!(!h.engine.take_step_request(), "the shot ended");
}

#[test]
fn an_event_step_sends_the_new_guidance_with_the_measured_dt() {
    let mut h = Harness::ready();
    h.connect_app(1);
    h.orbiting();
    h.run(400);
    // 10 ms after a tick: a step now carries the new speed, limited by the
    // acceleration over those 10 ms.
    h.now += 10 * MS;
    h.app(ShotRequest::ShotOptions { cruise_speed: 3.0 });
    assert!(h.engine.take_step_request());
    let out = h.engine.tick(h.now);
    let vel = cmds(&out)
        .into_iter()
        .find_map(|c| match c {
            Command::VelocityNed { vel_ned_mps, .. } => Some(vel_ned_mps),
            _ => None,
        })
        .expect("a setpoint");
    let speed = f64::from(vel[0]).hypot(f64::from(vel[1]));
    let accel = f64::from(h.engine.settings.limits.max_accel_mps2);
    assert!(speed > 0.0, "the setpoint reflects the new cruise speed");
    assert!(
        speed <= accel * 0.010 + 0.02,
        "within max_accel over the 10 ms: {speed}"
    );
}
