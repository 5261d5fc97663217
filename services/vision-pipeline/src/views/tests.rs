//! Tests of the virtual cameras: targeting modes, optics, zoom, view rays and offsets.

use super::*;
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

fn attitude(roll_deg: f64, pitch_deg: f64, yaw_deg: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(
        roll_deg.to_radians(),
        pitch_deg.to_radians(),
        yaw_deg.to_radians(),
    )
}

fn no_detection(_: u8) -> Option<Unit<Vector3<f64>>> {
    None
}

fn ctx(vehicle: UnitQuaternion<f64>) -> AimContext<'static> {
    AimContext {
        vehicle,
        position: None,
        detection: &no_detection,
        single_target: None,
        dt_s: 0.0,
    }
}

fn axis(q: &UnitQuaternion<f64>) -> YawPitch {
    YawPitch::of(&(q * Vector3::x())).unwrap()
}

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance
}

fn targeting(mode: u8, yaw: f64, pitch: f64, lock_flags: u8) -> Targeting {
    Targeting {
        mode,
        yaw,
        pitch,
        lock_flags,
        ..Targeting::default()
    }
}

fn here() -> GeoPosition {
    GeoPosition {
        lat_deg: 47.397_742,
        lon_deg: 8.545_594,
        alt_msl_m: 538.0,
    }
}

#[test]
fn a_new_camera_looks_ahead_level() {
    let mut cam = VirtualCamera::new(1.2);
    let q = cam.aim(&ctx(attitude(5.0, 10.0, 30.0))).unwrap();
    let a = axis(&q);
    assert!(close(a.yaw, 30f64.to_radians(), 1e-9), "{a:?}");
    assert!(close(a.pitch, 0.0, 1e-9), "{a:?}");
    // Roll locked: the view's right axis stays horizontal.
    assert!(close((q * Vector3::y()).z, 0.0, 1e-9));
    let s = cam.state(true, [0, 0, 1280, 720]);
    assert_eq!(s.aim_valid, 1);
    assert_eq!(s.lock_flags, LOCK_PITCH | LOCK_ROLL);
    assert!(close(f64::from(s.view_yaw_rad), 30f64.to_radians(), 1e-6));
    assert_eq!(s.crop_mode, CropMode::Rectified.to_wire());
}

#[test]
fn lock_flags_hold_axes_in_the_world() {
    let mut unlocked = VirtualCamera::new(1.0);
    unlocked
        .set_targeting(&targeting(0, 0.2, -0.3, LOCK_PITCH | LOCK_ROLL))
        .unwrap();
    let mut locked = VirtualCamera::new(1.0);
    locked
        .set_targeting(&targeting(0, 0.2, -0.3, LOCK_YAW | LOCK_PITCH | LOCK_ROLL))
        .unwrap();
    for cam in [&mut unlocked, &mut locked] {
        let a = axis(&cam.aim(&ctx(attitude(0.0, 0.0, 0.0))).unwrap());
        assert!(close(a.yaw, 0.2, 1e-9) && close(a.pitch, -0.3, 1e-9));
    }
    // The vehicle yaws 30°: the unlocked yaw follows, the locked one stays.
    let turned = ctx(attitude(0.0, 0.0, 30.0));
    let a = axis(&unlocked.aim(&turned).unwrap());
    assert!(close(a.yaw, 0.2 + 30f64.to_radians(), 1e-9), "{a:?}");
    let a = axis(&locked.aim(&turned).unwrap());
    assert!(close(a.yaw, 0.2, 1e-9), "{a:?}");
    // Pitch: the vehicle pitches up 10°; unlocked pitch follows the body.
    let mut free = VirtualCamera::new(1.0);
    free.set_targeting(&targeting(0, 0.0, -0.3, 0)).unwrap();
    let a = axis(&free.aim(&ctx(attitude(0.0, 10.0, 0.0))).unwrap());
    assert!(close(a.pitch, -0.3 + 10f64.to_radians(), 1e-9), "{a:?}");
    let a = axis(&locked.aim(&ctx(attitude(0.0, 10.0, 0.0))).unwrap());
    assert!(close(a.pitch, -0.3, 1e-9), "{a:?}");
    // Roll: unlocked rolls with the body, locked stays level.
    let q = free.aim(&ctx(attitude(20.0, 0.0, 0.0))).unwrap();
    assert!((q * Vector3::y()).z.abs() > 0.3);
    let q = locked.aim(&ctx(attitude(20.0, 0.0, 0.0))).unwrap();
    assert!(close((q * Vector3::y()).z, 0.0, 1e-9));
}

#[test]
fn euler_deltas_add_wrap_and_clamp() {
    let mut cam = VirtualCamera::new(1.0);
    let flags = LOCK_YAW | LOCK_PITCH | LOCK_ROLL;
    cam.set_targeting(&targeting(0, 3.0, 1.0, flags)).unwrap();
    let delta = Targeting {
        euler_delta: true,
        ..targeting(0, 0.5, 1.0, flags)
    };
    cam.set_targeting(&delta).unwrap();
    let s = cam.state(true, [0; 4]);
    assert!(close(f64::from(s.yaw_rad), 3.5 - 2.0 * PI, 1e-6), "{s:?}");
    assert!(close(f64::from(s.pitch_rad), FRAC_PI_2, 1e-6));
    assert_eq!(s.euler_delta, 1);
    let back = Targeting {
        euler_delta: true,
        ..targeting(0, -0.5, -0.25, flags)
    };
    cam.set_targeting(&back).unwrap();
    let a = axis(&cam.aim(&ctx(attitude(0.0, 0.0, 70.0))).unwrap());
    assert!(close(a.yaw, 3.0, 1e-9) && close(a.pitch, FRAC_PI_2 - 0.25, 1e-9));
}

#[test]
fn bad_modes_are_ignored_and_non_finite_refused() {
    let mut cam = VirtualCamera::new(1.0);
    cam.set_targeting(&targeting(0, 0.4, 0.0, 0)).unwrap();
    let before = cam.clone();
    assert!(matches!(
        cam.set_targeting(&targeting(4, 1.0, 0.0, 0)),
        Err(ViewError::Ignored(_))
    ));
    assert!(matches!(
        cam.set_targeting(&targeting(0, f64::NAN, 0.0, 0)),
        Err(ViewError::Invalid(_))
    ));
    assert_eq!(cam, before);
}

#[test]
fn offsets_move_the_aim_to_that_point_of_the_view() {
    let vehicle = attitude(0.0, 0.0, 40.0);
    let mut base = VirtualCamera::new(1.2);
    base.set_view_size(1280, 720);
    let centre = base.aim(&ctx(vehicle)).unwrap();
    let model = view_model(1280, 720, base.effective_hfov()).unwrap();
    let pose = CameraPose::from_parts(centre, 40f64.to_radians());
    for (x, y) in [(0.5, 0.0), (0.0, -0.5), (-0.7, 0.3)] {
        let mut cam = base.clone();
        let t = Targeting {
            x_offset: x,
            y_offset: y,
            ..targeting(0, 0.0, 0.0, LOCK_PITCH | LOCK_ROLL)
        };
        cam.set_targeting(&t).unwrap();
        let aimed = axis(&cam.aim(&ctx(vehicle)).unwrap());
        let expected = Direction::of_offset(&model, &pose, Offset { x, y }).unwrap();
        assert!(close(aimed.yaw, expected.global.yaw, 1e-9), "{x} {y}");
        assert!(close(aimed.pitch, expected.global.pitch, 1e-9), "{x} {y}");
        // Right is clockwise, up is up.
        let centre_dir = axis(&centre);
        assert_eq!(aimed.yaw > centre_dir.yaw + 1e-9, x > 0.0);
        assert_eq!(aimed.pitch > 1e-9, y > 0.0);
    }
}

#[test]
fn coordinal_keeps_a_ground_point_centred() {
    let ground = here().offset_by(&Vector3::new(30.0, -20.0, 50.0));
    let mut cam = VirtualCamera::new(1.0);
    let t = Targeting {
        latitude: ground.lat_deg,
        longitude: ground.lon_deg,
        altitude: -50.0,
        ..targeting(1, 0.0, 0.0, LOCK_PITCH | LOCK_ROLL)
    };
    cam.set_targeting(&t).unwrap();
    let model = view_model(1280, 720, cam.effective_hfov()).unwrap();
    for (north, east, yaw, roll) in [
        (0.0, 0.0, 0.0, 0.0),
        (-40.0, 10.0, 90.0, 5.0),
        (25.0, -35.0, -150.0, -10.0),
        (29.0, -21.0, 10.0, 0.0),
    ] {
        let position = here().offset_by(&Vector3::new(north, east, 0.0));
        let c = AimContext {
            position: Some(position),
            ..ctx(attitude(roll, 3.0, yaw))
        };
        let q = cam.aim(&c).unwrap();
        let pose = CameraPose::from_parts(q, yaw.to_radians());
        let ray = pose.ned_to_camera(&position.ned_to(&ground));
        let pixel = model.ray_to_pixel(&ray).unwrap();
        assert!((pixel - Point2::new(640.0, 360.0)).norm() < 0.5, "{pixel}");
    }
    let s = cam.state(true, [0, 0, 1280, 720]);
    assert_eq!(s.targeting_mode, TargetingMode::Coordinal.to_wire());
    assert!(close(f64::from(s.target_alt_rel_m), -50.0, 1e-6));
    // No position: not resolvable, the last aim is held.
    let last = cam.last_aim();
    assert!(cam.aim(&ctx(attitude(0.0, 0.0, 0.0))).is_none());
    assert_eq!(cam.state(true, [0; 4]).aim_valid, 0);
    assert_eq!(cam.last_aim(), last);
}

#[test]
fn roi_is_absolute_and_roi_none_holds_the_direction() {
    let target = GeoPosition {
        alt_msl_m: 500.0,
        ..here().offset_by(&Vector3::new(0.0, 38.0, 0.0))
    };
    let mut cam = VirtualCamera::new(1.0);
    cam.roi(target);
    let c = AimContext {
        position: Some(here()),
        ..ctx(attitude(0.0, 0.0, -60.0))
    };
    let a = axis(&cam.aim(&c).unwrap());
    // 38 m east, 38 m below: yaw 90°, pitch −45°.
    assert!(close(a.yaw, FRAC_PI_2, 1e-6) && close(a.pitch, -FRAC_PI_4, 1e-6));
    assert!(close(
        f64::from(cam.state(true, [0; 4]).target_alt_rel_m),
        -38.0,
        1e-3
    ));
    cam.roi_none();
    assert_eq!(cam.targeting_mode(), TargetingMode::Directional);
    let a = axis(&cam.aim(&ctx(attitude(0.0, 0.0, -60.0))).unwrap());
    assert!(close(a.yaw, FRAC_PI_2, 1e-6) && close(a.pitch, -FRAC_PI_4, 1e-6));
}

#[test]
fn detection_mode_picks_the_nearest_and_follows_its_id() {
    let east = Unit::new_normalize(Vector3::new(0.0, 1.0, 0.2));
    let north = Unit::new_normalize(Vector3::new(1.0, 0.05, 0.1));
    let visible = std::cell::Cell::new(true);
    let lookup = |id: u8| match id {
        7 => Some(east),
        12 if visible.get() => Some(north),
        _ => None,
    };
    let mut cam = VirtualCamera::new(1.0);
    cam.set_targeting(&targeting(2, 0.0, 0.0, LOCK_PITCH | LOCK_ROLL))
        .unwrap();
    let c = AimContext {
        detection: &lookup,
        ..ctx(attitude(0.0, 0.0, 0.0))
    };
    let q = cam.aim(&c).unwrap();
    assert_eq!(cam.detection_id(), 12);
    assert!(((q * Vector3::x()) - north.into_inner()).norm() < 1e-9);
    // Lost: holds the last aim, keeps the id.
    visible.set(false);
    assert!(cam.aim(&c).is_none());
    assert_eq!(cam.detection_id(), 12);
    assert_eq!(cam.last_aim(), Some(q));
    assert_eq!(cam.state(true, [0; 4]).aim_valid, 0);
    // Explicit id.
    cam.follow_detection(7);
    let q = cam.aim(&c).unwrap();
    assert!(((q * Vector3::x()) - east.into_inner()).norm() < 1e-9);
    assert_eq!(cam.state(true, [0; 4]).detection_id, 7);
}

#[test]
fn single_target_mode_aims_at_the_tracker() {
    let target = Unit::new_normalize(Vector3::new(-1.0, -1.0, 0.5));
    let mut cam = VirtualCamera::new(1.0);
    cam.set_targeting(&targeting(3, 0.0, 0.0, LOCK_PITCH | LOCK_ROLL))
        .unwrap();
    assert!(cam.aim(&ctx(attitude(0.0, 0.0, 0.0))).is_none());
    let c = AimContext {
        single_target: Some(target),
        ..ctx(attitude(0.0, 0.0, 0.0))
    };
    let q = cam.aim(&c).unwrap();
    assert!(((q * Vector3::x()) - target.into_inner()).norm() < 1e-9);
}

#[test]
fn zoom_narrows_the_view() {
    let mut cam = VirtualCamera::new(1.6);
    let optics = |zoom, fov, crop_mode| Optics {
        zoom,
        fov,
        crop_mode,
    };
    cam.set_optics(&optics(32, 1.6, 1)).unwrap();
    assert!(close(cam.effective_hfov(), 0.8, 1e-12));
    cam.set_optics(&optics(-32, 1.0, 2)).unwrap();
    assert!(close(cam.effective_hfov(), 2.0, 1e-12));
    assert_eq!(cam.crop_mode(), CropMode::Panoramic);
    cam.set_optics(&optics(127, 1.0, 0)).unwrap();
    assert!(close(cam.zoom_factor(), 2f64.powf(127.0 / 32.0), 1e-12));
    assert!(close(cam.effective_hfov(), FOV_MIN_RAD, 1e-12));
    cam.set_optics(&optics(-127, 3.0, 0)).unwrap();
    assert!(close(cam.effective_hfov(), FOV_MAX_RAD, 1e-12));
    // An out-of-range FOV is ignored, the rest applied.
    assert!(matches!(
        cam.set_optics(&optics(0, 0.05, 1)),
        Err(ViewError::Ignored(_))
    ));
    assert!(close(cam.effective_hfov(), 3.0, 1e-12));
    assert_eq!(cam.state(true, [0; 4]).zoom, 0);
    assert!(matches!(
        cam.set_optics(&optics(0, 1.0, 3)),
        Err(ViewError::Invalid(_))
    ));
}

#[test]
fn mavlink_zoom_types() {
    let mut cam = VirtualCamera::new(1.0);
    cam.zoom_mavlink(0, 1.0).unwrap();
    cam.zoom_mavlink(0, 1.0).unwrap();
    assert_eq!(cam.zoom(), 32.0);
    cam.zoom_mavlink(0, -1.0).unwrap();
    assert_eq!(cam.zoom(), 16.0);
    assert!(cam.zoom_mavlink(0, 2.0).is_err());
    cam.zoom_mavlink(2, 0.0).unwrap();
    assert_eq!(cam.zoom(), -127.0);
    cam.zoom_mavlink(2, 100.0).unwrap();
    assert_eq!(cam.zoom(), 127.0);
    cam.zoom_mavlink(2, 50.0).unwrap();
    assert_eq!(cam.zoom(), 0.0);
    assert!(cam.zoom_mavlink(2, 101.0).is_err());
    // Continuous: integrated per aim.
    cam.zoom_mavlink(1, 1.0).unwrap();
    let mut c = ctx(attitude(0.0, 0.0, 0.0));
    c.dt_s = 0.5;
    cam.aim(&c);
    cam.aim(&c);
    assert!(close(cam.zoom(), 32.0, 1e-9));
    cam.zoom_mavlink(1, 0.0).unwrap();
    cam.aim(&c);
    assert!(close(cam.zoom(), 32.0, 1e-9));
    assert_eq!(
        cam.zoom_mavlink(3, 35.0),
        Err(ViewError::Invalid(
            "zoom by focal length is not supported, virtual cameras have no focal length".into()
        ))
    );
    assert!(cam.zoom_mavlink(1, f32::NAN).is_err());
    assert!(cam.zoom_mavlink(0, f32::INFINITY).is_err());
    assert!(cam.zoom_mavlink(9, 0.0).is_err());
    assert!(close(cam.zoom(), 32.0, 1e-9));
}

#[test]
fn gimbal_angles_and_rates() {
    let mut cam = VirtualCamera::new(1.0);
    // Relative yaw: follows the heading.
    cam.gimbal(Some(0.5), Some(-0.2), None, None, false)
        .unwrap();
    let a = axis(&cam.aim(&ctx(attitude(0.0, 5.0, 20.0))).unwrap());
    assert!(close(a.yaw, 0.5 + 20f64.to_radians(), 1e-9));
    assert!(close(a.pitch, -0.2, 1e-9));
    // Global yaw.
    cam.gimbal(Some(-1.0), None, None, None, true).unwrap();
    let a = axis(&cam.aim(&ctx(attitude(0.0, 5.0, 20.0))).unwrap());
    assert!(close(a.yaw, -1.0, 1e-9) && close(a.pitch, -0.2, 1e-9));
    // Rates turn the view until the next command.
    cam.gimbal(None, None, Some(0.1), Some(0.05), true).unwrap();
    let mut c = ctx(attitude(0.0, 0.0, 0.0));
    c.dt_s = 1.0;
    cam.aim(&c);
    let a = axis(&cam.aim(&c).unwrap());
    assert!(
        close(a.yaw, -0.8, 1e-9) && close(a.pitch, -0.1, 1e-9),
        "{a:?}"
    );
    cam.gimbal(None, None, None, None, true).unwrap();
    let a = axis(&cam.aim(&c).unwrap());
    assert!(close(a.yaw, -0.8, 1e-9));
    assert!(cam.gimbal(Some(f64::NAN), None, None, None, true).is_err());
    // Switching the yaw frame keeps the direction.
    cam.aim(&ctx(attitude(0.0, 0.0, 30.0)));
    cam.gimbal(None, None, None, None, false).unwrap();
    let a = axis(&cam.aim(&ctx(attitude(0.0, 0.0, 30.0))).unwrap());
    assert!(close(a.yaw, -0.8, 1e-9), "{a:?}");
}

#[test]
fn cam_offset_of_the_published_state() {
    let mut cam = VirtualCamera::new(1.2);
    cam.set_targeting(&targeting(0, 0.3, -0.4, LOCK_YAW | LOCK_PITCH | LOCK_ROLL))
        .unwrap();
    let q = cam.aim(&ctx(attitude(0.0, 0.0, 50.0))).unwrap();
    let s = cam.state(true, [0, 0, 640, 360]);
    let heading = 50f64.to_radians();
    let d = cam_offset(&s, heading, 0.0, 0.0).unwrap();
    assert!(close(d.global.yaw, 0.3, 1e-6) && close(d.global.pitch, -0.4, 1e-6));
    assert!(close(d.heading.yaw, 0.3 - heading, 1e-6));
    assert!(close(d.camera.yaw, 0.0, 1e-6));
    // The right edge is half the FOV to the right of the centre, in the view.
    let d = cam_offset(&s, heading, 1.0, 0.0).unwrap();
    assert!(close(d.camera.yaw, 0.6, 1e-6), "{d:?}");
    let expected = YawPitch::of(
        &(q * YawPitch {
            yaw: 0.6,
            pitch: 0.0,
        }
        .direction()
        .into_inner()),
    )
    .unwrap();
    assert!(close(d.global.yaw, expected.yaw, 1e-6));
    // Panoramic: yaw linear across the width too.
    let mut pano = s;
    pano.crop_mode = CropMode::Panoramic.to_wire();
    let d = cam_offset(&pano, heading, 0.5, 0.0).unwrap();
    assert!(close(d.camera.yaw, 0.3, 1e-6));
    // Nothing to answer from.
    assert!(cam_offset(&cam.state(true, [0, 0, 0, 360]), heading, 0.0, 0.0).is_none());
    assert!(cam_offset(
        &VirtualCamera::new(1.0).state(true, [0, 0, 640, 360]),
        0.0,
        0.0,
        0.0
    )
    .is_none());
}

#[test]
fn view_models_refuse_bad_sizes() {
    assert!(view_model(0, 720, 1.0).is_none());
    assert!(view_model(1280, 720, 0.0).is_none());
    assert!(view_model(1280, 720, PI).is_none());
    let m = view_model(1280, 720, FRAC_PI_2).unwrap();
    let p = m.ray_to_pixel(&Vector3::new(1.0, 1.0, 0.0)).unwrap();
    assert!(close(p.x, 1280.0, 1e-9));
    assert!(view_ray(CropMode::Rectified, 10.0, 10.0, 4.0, 0.0, 0.0).is_none());
    assert!(view_ray(CropMode::Panoramic, 10.0, 10.0, 4.0, 0.0, 5.0).is_some());
}
