//! The GoPro model and requests.

use skymesh_ipc_types::shot_api::{GoProState, ShotEvent, ShotRequest};
use skymesh_ipc_types::{
    AckResult, Command, CommandKind, GoProStatus, PayloadState, RefusalReason,
};

use super::*;

fn gopro(mode: u8, recording: u8) -> PayloadState {
    PayloadState {
        gopro_status: GoProStatus::Connected.to_wire(),
        gopro_capture_mode: mode,
        gopro_recording: recording,
        gimbal_valid: 1,
        ..PayloadState::default()
    }
}

fn states(out: &Outputs) -> Vec<GoProState> {
    out.to_app
        .iter()
        .filter_map(|m| match m {
            ShotEvent::GoProV1State(s) | ShotEvent::GoProV2State(s) => Some(*s),
            _ => None,
        })
        .collect()
}

#[test]
fn state_is_sent_v1_then_v2_on_connect_request_and_change() {
    let mut h = Harness::new();
    h.vehicle_ok();
    let out = h.connect_app(1);
    assert_eq!(out.to_app[0], ShotEvent::CurrentShot(-1));
    let s = states(&out);
    assert_eq!(s.len(), 2);
    assert!(matches!(out.to_app[1], ShotEvent::GoProV1State(_)));
    assert!(matches!(out.to_app[2], ShotEvent::GoProV2State(_)));
    assert_eq!((s[0].version, s[1].version), (1, 2));
    assert_eq!(s[1].status, 0, "no GoPro heard yet");

    let out = h.payload(gopro(0, 0));
    let s = states(&out);
    assert_eq!(s.len(), 2);
    assert_eq!(s[1].status, 2);
    assert_eq!(s[1].gimbal_enabled, 1);
    // The same again: no change, nothing sent.
    assert!(h.payload(gopro(0, 0)).to_app.is_empty());
    let out = h.payload(gopro(0, 1));
    assert_eq!(states(&out)[1].recording, 1);

    let out = h.app(ShotRequest::GoProRequestState);
    assert_eq!(states(&out).len(), 2);
    assert_eq!(out.to_app.len(), 2);
}

#[test]
fn record_in_video_mode_is_shutter_on_off_and_toggles_from_the_recording_flag() {
    let mut h = Harness::ready();
    h.payload(gopro(0, 0));
    let out = h.app(ShotRequest::GoProRecord(1));
    assert_eq!(
        cmds(&out),
        [
            Command::GrabPayloadAuthority,
            Command::GoProSet {
                command: 2,
                value: [1, 0, 0, 0]
            }
        ]
    );
    // Toggle while not recording → start; while recording → stop.
    let out = h.app(ShotRequest::GoProRecord(2));
    assert_eq!(
        cmds(&out)[1],
        Command::GoProSet {
            command: 2,
            value: [1, 0, 0, 0]
        }
    );
    h.payload(gopro(0, 1));
    let out = h.app(ShotRequest::GoProRecord(2));
    assert_eq!(
        cmds(&out)[1],
        Command::GoProSet {
            command: 2,
            value: [0, 0, 0, 0]
        }
    );
    let out = h.app(ShotRequest::GoProRecord(0));
    assert_eq!(
        cmds(&out)[1],
        Command::GoProSet {
            command: 2,
            value: [0, 0, 0, 0]
        }
    );
}

#[test]
fn record_in_photo_mode_takes_a_photo() {
    let mut h = Harness::ready();
    h.payload(gopro(1, 0));
    for what in [1, 2] {
        let out = h.app(ShotRequest::GoProRecord(what));
        assert_eq!(
            cmds(&out)[1],
            Command::GoProSet {
                command: 2,
                value: [1, 0, 0, 0]
            }
        );
    }
    assert!(h.app(ShotRequest::GoProRecord(0)).commands.is_empty());
    // Unknown capture mode: refused, nothing sent.
    h.payload(gopro(255, 0));
    let out = h.app(ShotRequest::GoProRecord(1));
    assert!(out.commands.is_empty());
    assert!(matches!(&out.to_app[..], [ShotEvent::Error(_)]));
}

#[test]
fn accepted_settings_change_the_model_and_are_sent() {
    let mut h = Harness::ready();
    h.payload(gopro(0, 0));
    let out = h.app(ShotRequest::GoProSetExtendedRequest {
        command: 5,
        value: [3, 7, 1, 0],
    });
    let set = find(&out, CommandKind::GoProSet).unwrap();
    assert!(out.to_app.is_empty(), "nothing changes before the ack");
    let out = h.ack(&set, AckResult::Accepted, RefusalReason::None);
    let s = states(&out);
    assert_eq!(s.len(), 2);
    assert_eq!(
        (
            s[1].video_resolution,
            s[1].video_fps,
            s[1].video_fov,
            s[1].ntsc_pal
        ),
        (3, 7, 1, 0)
    );
    assert_eq!(
        kinds(&out),
        [CommandKind::ReleasePayloadAuthority],
        "payload authority given back once idle"
    );

    // The legacy request sets the first byte; a refusal is reported.
    let out = h.app(ShotRequest::GoProSetRequest {
        command: 9,
        value: 1,
    });
    let set = find(&out, CommandKind::GoProSet).unwrap();
    assert_eq!(
        set.command().unwrap(),
        Command::GoProSet {
            command: 9,
            value: [1, 0, 0, 0]
        }
    );
    let out = h.ack(&set, AckResult::Refused, RefusalReason::Unsupported);
    assert!(matches!(&out.to_app[0], ShotEvent::Error(t) if t.contains("unsupported")));
    assert_eq!(h.engine.gopro_state().video_protune, 0);

    // Out of range commands and values are refused before anything is sent.
    for bad in [
        ShotRequest::GoProSetRequest {
            command: 32,
            value: 0,
        },
        ShotRequest::GoProSetRequest {
            command: 1,
            value: 256,
        },
    ] {
        let out = h.app(bad);
        assert!(out.commands.is_empty());
        assert!(matches!(&out.to_app[..], [ShotEvent::Error(_)]));
    }
}

#[test]
fn disabled_gopro_refuses_requests_reports_status_0_and_persists() {
    let mut h = Harness::ready();
    h.payload(gopro(0, 0));
    let out = h.app(ShotRequest::GoProSetEnabled(0));
    assert_eq!(states(&out)[1].status, 0);
    let out = h.app(ShotRequest::GoProRecord(1));
    assert!(out.commands.is_empty());
    assert!(matches!(&out.to_app[..], [ShotEvent::Error(t)] if t.contains("disabled")));

    let mut again = Harness::on_file(&h.state_file);
    again.vehicle_ok();
    again.payload(gopro(0, 0));
    assert_eq!(again.engine.gopro_state().status, 0);
    again.connect_app(1);
    let out = again.app(ShotRequest::GoProSetEnabled(1));
    assert_eq!(states(&out)[1].status, 2);
}

#[test]
fn the_camera_button_records_with_a_gopro_and_takes_a_photo_without() {
    let mut h = Harness::ready();
    // No GoPro heard: a photo through the MAVLink camera protocol.
    let out = h.button(Button::CameraClick);
    assert!(cmds(&out).contains(&Command::CameraCapture));
    // A GoPro in video mode, not recording: the button starts recording (SHUTTER 1).
    h.payload(gopro(0, 0));
    let out = h.button(Button::CameraClick);
    let sent = cmds(&out);
    assert!(sent.contains(&Command::GoProSet {
        command: 2,
        value: [1, 0, 0, 0]
    }));
    assert!(!sent.contains(&Command::CameraCapture));
}
