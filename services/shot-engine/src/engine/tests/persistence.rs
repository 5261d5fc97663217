//! Button mappings (get, set, persisted) and the restart after a crash.

use skymesh_ipc_types::shot_api::shots::{CABLECAM, NONE, ORBIT, SELFIE};
use skymesh_ipc_types::shot_api::{ButtonSetting, ShotEvent, ShotRequest};
use skymesh_ipc_types::{Button, Command, FlightMode};

use super::*;

const A: i32 = 4;
const B: i32 = 5;
const PRESS: i32 = 0;

fn get(h: &mut Harness, button: i32, event: i32) -> ButtonSetting {
    let out = h.app(ShotRequest::GetButtonSetting(ButtonSetting {
        button,
        event,
        shot: -1,
        mode: -1,
    }));
    match &out.to_app[..] {
        [ShotEvent::ButtonSetting(s)] => *s,
        other => panic!("{other:?}"),
    }
}

#[test]
fn button_settings_are_answered_stored_and_survive_a_new_engine() {
    let mut h = Harness::ready();
    // Factory defaults.
    assert_eq!(
        get(&mut h, A, PRESS),
        ButtonSetting {
            button: A,
            event: PRESS,
            shot: CABLECAM,
            mode: -1
        }
    );
    assert_eq!(get(&mut h, B, PRESS).shot, ORBIT);
    // Other buttons and events are not mapped.
    assert_eq!(get(&mut h, 8, PRESS).shot, -1);
    assert_eq!(get(&mut h, A, 3).shot, -1);

    let out = h.app(ShotRequest::SetButtonSetting(ButtonSetting {
        button: A,
        event: PRESS,
        shot: SELFIE,
        mode: -1,
    }));
    assert!(out.to_app.is_empty(), "SET is not answered");
    h.app(ShotRequest::SetButtonSetting(ButtonSetting {
        button: B,
        event: PRESS,
        shot: -1,
        mode: 5,
    }));
    // Only A and B.
    let out = h.app(ShotRequest::SetButtonSetting(ButtonSetting {
        button: 8,
        event: PRESS,
        shot: ORBIT,
        mode: -1,
    }));
    assert!(matches!(&out.to_app[..], [ShotEvent::Error(t)] if t.contains("only the A and B")));

    let mut again = Harness::on_file(&h.state_file);
    again.vehicle_ok();
    again.connect_app(1);
    assert_eq!(get(&mut again, A, PRESS).shot, SELFIE);
    let b = get(&mut again, B, PRESS);
    assert_eq!((b.shot, b.mode), (-1, 5));

    // B mapped to ArduCopter mode 5 (LOITER): a mode change, authority given back.
    let out = again.button(Button::B);
    assert_eq!(
        cmds(&out),
        [
            Command::SetMode(FlightMode::Loiter),
            Command::ReleaseFlightAuthority
        ]
    );
}

#[test]
fn a_restart_never_resumes_the_shot_and_tells_the_app_once_connected() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("state.json");
    {
        let mut h = Harness::on_file(&path);
        h.vehicle_ok();
        h.connect_app(1);
        h.orbiting();
        h.run(200);
        // The process dies here: no exit, the file still says orbit.
    }
    let mut h = Harness::on_file(&path);
    assert_eq!(h.engine.last_exit(), "restarted");
    assert_eq!(h.engine.current_shot(), NONE);
    h.vehicle_ok();
    h.set_mode(FlightMode::Guided);
    let quiet = h.run(1_000);
    assert!(
        quiet.commands.is_empty(),
        "a restart sends no flight command"
    );
    assert_eq!(quiet.status.unwrap().last_exit.as_str(), "restarted");

    let out = h.connect_app(7);
    assert_eq!(
        out.to_app[..2],
        [
            ShotEvent::Error("shot engine restarted; orbit ended".into()),
            ShotEvent::CurrentShot(NONE)
        ]
    );
    assert!(matches!(out.to_app[2], ShotEvent::GoProV1State(_)));
    // Told once.
    h.session(7, false);
    let out = h.connect_app(8);
    assert_eq!(out.to_app[0], ShotEvent::CurrentShot(NONE));

    // The pilot's FLY gives the sticks back (the vehicle was left braked in GUIDED).
    let out = h.button(Button::Fly);
    assert_eq!(
        cmds(&out),
        [
            Command::SetMode(FlightMode::Loiter),
            Command::ReleaseFlightAuthority
        ]
    );

    // And a third start finds nothing to report.
    let h = Harness::on_file(&path);
    assert_eq!(h.engine.last_exit(), "");
}

#[test]
fn the_active_shot_is_recorded_while_it_runs() {
    let mut h = Harness::ready();
    h.app(ShotRequest::StartShot(SELFIE));
    let (store, _) = crate::persist::Store::open(&h.state_file);
    assert_eq!(store.state().active_shot, Some(SELFIE));
    h.app(ShotRequest::StartShot(NONE));
    let (store, _) = crate::persist::Store::open(&h.state_file);
    assert_eq!(store.state().active_shot, None);
}
