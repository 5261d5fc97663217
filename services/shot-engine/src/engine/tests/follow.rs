//! Follow: options V1 then V2, flying from the first phone position, target loss.

use skymesh_ipc_types::shot_api::shots::FOLLOW;
use skymesh_ipc_types::shot_api::{ShotEvent, ShotRequest};
use skymesh_ipc_types::{CommandKind, FlightMode};

use super::*;
use crate::engine::shot::ShotKind;
use crate::shots::FollowMode;

fn follow_mode(h: &Harness) -> FollowMode {
    match &h.engine.active.as_ref().unwrap().kind {
        ShotKind::Follow(f) => f.mode(),
        _ => panic!("not following"),
    }
}

#[test]
fn follow_options_are_answered_v1_then_v2() {
    let mut h = Harness::ready();
    let out = h.app(ShotRequest::StartShot(FOLLOW));
    assert_eq!(
        out.to_app,
        [
            ShotEvent::CurrentShot(FOLLOW),
            ShotEvent::FollowOptions {
                cruise_speed: 0.0,
                look_at: 0
            },
            ShotEvent::FollowOptionsV2 {
                cruise_speed: 0.0,
                look_at: 0,
                follow_preference: 0
            }
        ]
    );
    assert_eq!(follow_mode(&h), FollowMode::Orbit);

    let out = h.app(ShotRequest::FollowOptionsV2 {
        cruise_speed: 1.5,
        look_at: 0,
        follow_preference: 2,
    });
    assert_eq!(
        out.to_app,
        [
            ShotEvent::FollowOptions {
                cruise_speed: 1.5,
                look_at: 0
            },
            ShotEvent::FollowOptionsV2 {
                cruise_speed: 1.5,
                look_at: 0,
                follow_preference: 2
            }
        ]
    );
    assert_eq!(follow_mode(&h), FollowMode::Leash);

    // V1 keeps the preference; look-at wins over it.
    let out = h.app(ShotRequest::FollowOptions {
        cruise_speed: -1.0,
        look_at: 1,
    });
    assert_eq!(
        out.to_app[1],
        ShotEvent::FollowOptionsV2 {
            cruise_speed: -1.0,
            look_at: 1,
            follow_preference: 2
        }
    );
    assert_eq!(follow_mode(&h), FollowMode::LookAt);
    h.app(ShotRequest::FollowOptionsV2 {
        cruise_speed: 0.0,
        look_at: 0,
        follow_preference: 1,
    });
    assert_eq!(follow_mode(&h), FollowMode::FreeLook);
}

#[test]
fn follow_flies_from_the_first_position_and_holds_when_positions_stop() {
    let mut h = Harness::ready();
    h.app(ShotRequest::StartShot(FOLLOW));
    // No position yet: setup, no commands.
    assert!(h.run(400).commands.is_empty());
    assert!(!h.engine.is_flying());

    // Several positions within one tick: only the newest counts.
    h.fix(10.0);
    h.fix(12.0);
    let out = h.tick();
    assert_eq!(
        kinds(&out)[..2],
        [CommandKind::GrabFlightAuthority, CommandKind::SetMode]
    );
    assert!(find(&out, CommandKind::VelocityNed).is_some());
    h.set_mode(FlightMode::Guided);

    // Positions keep coming: no complaint.
    for _ in 0..50 {
        h.fix(12.0);
        assert!(h.tick().to_app.is_empty());
    }
    // They stop: after follow_lost_s (3 s) one error, and zero velocity.
    let out = h.run(4_000);
    let errors: Vec<_> = out
        .to_app
        .iter()
        .filter(|m| matches!(m, ShotEvent::Error(_)))
        .collect();
    assert_eq!(
        errors,
        [&ShotEvent::Error(
            "follow: no phone position for 3 s, holding".into()
        )]
    );
    let last = cmds(&h.tick())
        .into_iter()
        .find_map(|c| match c {
            skymesh_ipc_types::Command::VelocityNed { vel_ned_mps, .. } => Some(vel_ned_mps),
            _ => None,
        })
        .unwrap();
    assert_eq!(last, [0.0; 3]);
    assert!(h.engine.is_flying(), "holding, not ended");

    // Positions return: resumes, and a later loss is reported again.
    h.fix(12.0);
    assert!(h.tick().to_app.is_empty());
    let out = h.run(4_000);
    assert_eq!(
        out.to_app
            .iter()
            .filter(|m| matches!(m, ShotEvent::Error(_)))
            .count(),
        1
    );
}

#[test]
fn follow_positions_outside_follow_are_ignored() {
    let mut h = Harness::ready();
    h.fix(10.0);
    assert!(h.tick().commands.is_empty());
    h.orbiting();
    h.tick();
    h.fix(10.0);
    let out = h.tick();
    assert_eq!(kinds(&out), [], "orbit ignores phone positions");
}
