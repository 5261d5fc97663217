//! What this version does not implement is answered honestly, and counted.

use solo_proto::shots::{MULTIPOINT, NONE, ORBIT, PANO, REWIND, RTL, TRANSECT, ZIPLINE};
use solo_proto::{GeofenceData, SoloMessage, SplinePoint};

use super::*;

fn error_text(out: &Outputs) -> String {
    match &out.to_app[0] {
        SoloMessage::ShotManagerError(t) => t.clone(),
        other => panic!("{other:?}"),
    }
}

#[test]
fn unimplemented_shots_are_refused_and_the_app_leaves_the_shot_screen() {
    let mut h = Harness::ready();
    for shot in [ZIPLINE, MULTIPOINT, PANO, REWIND, TRANSECT, RTL] {
        let out = h.app(SoloMessage::SetCurrentShot(shot));
        assert!(
            error_text(&out).ends_with("is not implemented in this skymesh version"),
            "{shot}: {:?}",
            out.to_app
        );
        assert_eq!(out.to_app[1], SoloMessage::GetCurrentShot(NONE));
        assert!(out.commands.is_empty());
    }
    assert_eq!(
        error_text(&h.app(SoloMessage::SetCurrentShot(ZIPLINE))),
        "zipline is not implemented in this skymesh version"
    );
    assert_eq!(
        h.counter("skymesh_shot_unimplemented_requests_total", &[]),
        7
    );

    // In a shot: the shot keeps running and the app is told so.
    h.orbiting();
    let out = h.app(SoloMessage::SetCurrentShot(PANO));
    assert_eq!(out.to_app[1], SoloMessage::GetCurrentShot(ORBIT));
    assert!(h.engine.is_flying());
}

#[test]
fn spline_point_and_geofence_requests_get_their_one_reply() {
    let mut h = Harness::ready();
    let p = SplinePoint {
        version: 0,
        abs_alt_ref_m: 584.0,
        index: 3,
        lat_deg: LAT,
        lon_deg: LON,
        alt_m: 10.0,
        pitch_deg: -20.0,
        yaw_deg: 90.0,
        u_position: 0.0,
        status: 0,
    };
    let out = h.app(SoloMessage::SplinePoint(p));
    assert!(error_text(&out).starts_with("multipoint cable cam is not implemented"));
    assert_eq!(
        out.to_app[1],
        SoloMessage::SplinePoint(SplinePoint { status: -4, ..p })
    );
    assert_eq!(out.to_app.len(), 2);

    let fence = GeofenceData {
        coord: vec![vec![[LAT, LON], [LAT + 0.001, LON], [LAT, LON + 0.001]]],
        sub_coord: vec![vec![[LAT, LON], [LAT + 0.0009, LON], [LAT, LON + 0.0009]]],
        kinds: vec![0],
    };
    for msg in [
        SoloMessage::GeofenceSetData(fence),
        SoloMessage::GeofenceClear,
    ] {
        let out = h.app(msg);
        assert!(error_text(&out).starts_with("geofence is not implemented"));
        assert_eq!(
            out.to_app[1],
            SoloMessage::GeofenceSetAck {
                count: 0,
                valid: false
            }
        );
    }

    for msg in [
        SoloMessage::SplineRecord,
        SoloMessage::ZiplineLock,
        SoloMessage::HomeLocation(loc(0.0)),
        SoloMessage::InspectStart {
            takeoff_alt_m: 10.0,
        },
        SoloMessage::ScanStart,
        SoloMessage::SurveyStart,
    ] {
        let name = msg.name();
        let out = h.app(msg);
        assert!(
            error_text(&out).contains("is not implemented"),
            "{name}: {:?}",
            out.to_app
        );
        assert_eq!(out.to_app.len(), 1, "{name}");
    }
    assert_eq!(
        h.counter("skymesh_shot_unimplemented_requests_total", &[]),
        9
    );
}

#[test]
fn app_messages_are_counted_by_type() {
    let mut h = Harness::ready();
    h.app(SoloMessage::SetCurrentShot(ORBIT));
    h.app(SoloMessage::SetCurrentShot(NONE));
    let in_name = SoloMessage::SetCurrentShot(0).name();
    let out_name = SoloMessage::GetCurrentShot(0).name();
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
