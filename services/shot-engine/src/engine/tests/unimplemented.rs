//! What this version does not implement is answered honestly, and counted.

use skymesh_ipc_types::shot_api::shots::{NONE, ORBIT, RTL, TRANSECT};
use skymesh_ipc_types::shot_api::{ShotEvent, ShotRequest};

use super::*;

fn error_text(out: &Outputs) -> String {
    match &out.to_app[0] {
        ShotEvent::Error(t) => t.clone(),
        other => panic!("{other:?}"),
    }
}

#[test]
fn unimplemented_shots_are_refused_and_the_app_leaves_the_shot_screen() {
    let mut h = Harness::ready();
    for shot in [TRANSECT, RTL] {
        let out = h.app(ShotRequest::StartShot(shot));
        assert!(
            error_text(&out).ends_with("is not implemented in this skymesh version"),
            "{shot}: {:?}",
            out.to_app
        );
        assert_eq!(out.to_app[1], ShotEvent::CurrentShot(NONE));
        assert!(out.commands.is_empty());
    }
    assert_eq!(
        error_text(&h.app(ShotRequest::StartShot(TRANSECT))),
        "transect is not implemented in this skymesh version"
    );
    assert_eq!(
        h.counter("skymesh_shot_unimplemented_requests_total", &[]),
        3
    );

    // In a shot: the shot keeps running and the app is told so.
    h.orbiting();
    let out = h.app(ShotRequest::StartShot(RTL));
    assert_eq!(out.to_app[1], ShotEvent::CurrentShot(ORBIT));
    assert!(h.engine.is_flying());
}

#[test]
fn app_messages_are_counted_by_type() {
    let mut h = Harness::ready();
    h.app(ShotRequest::StartShot(ORBIT));
    h.app(ShotRequest::StartShot(NONE));
    let in_name = ShotRequest::StartShot(0).name();
    let out_name = ShotEvent::CurrentShot(0).name();
    assert_eq!(
        h.counter("skymesh_shot_app_messages_in_total", &[("msg", in_name)]),
        2
    );
    // Connect (1) + entry (1) + exit (1).
    assert_eq!(
        h.counter("skymesh_shot_app_messages_out_total", &[("msg", out_name)]),
        3
    );
}
