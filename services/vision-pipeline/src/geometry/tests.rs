//! Tests of the camera geometry: projections, poses, directions, ground.

use super::model::{equidistant, equidistant_fold, radial_fold_r2};
use super::*;
use proptest::prelude::*;
use skymesh_ipc_types::frame::{CameraIntrinsics, LensModel};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

const W: f64 = 1920.0;
const H: f64 = 1080.0;

fn vehicle() -> GeoPosition {
    GeoPosition {
        lat_deg: 47.397_742,
        lon_deg: 8.545_594,
        alt_msl_m: 538.0,
    }
}

fn pinhole_90() -> CameraModel {
    CameraModel::from_hfov(W, H, FRAC_PI_2).unwrap()
}

fn distorted_pinhole() -> CameraModel {
    CameraModel::new(
        W,
        H,
        1000.0,
        1002.0,
        955.0,
        545.0,
        Lens::Pinhole {
            k1: -0.12,
            k2: 0.03,
            p1: 0.001,
            p2: -0.0007,
        },
    )
    .unwrap()
}

fn fisheye() -> CameraModel {
    // ~190° diagonal: f = 600 px, θd at the corner ≈ 1.84 rad.
    CameraModel::new(
        W,
        H,
        600.0,
        600.0,
        960.0,
        540.0,
        Lens::Fisheye {
            k: [0.02, -0.005, 0.001, -0.0001],
        },
    )
    .unwrap()
}

fn attitude(roll_deg: f64, pitch_deg: f64, yaw_deg: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(
        roll_deg.to_radians(),
        pitch_deg.to_radians(),
        yaw_deg.to_radians(),
    )
}

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance
}

#[test]
fn nadir_centre_pixel_sees_the_point_below() {
    let model = pinhole_90();
    let pose = CameraPose::new(attitude(0.0, 0.0, 30.0), &Mount::nadir());
    let centre = model.offset_to_pixel(Offset { x: 0.0, y: 0.0 });
    assert_eq!(centre, Point2::new(960.0, 540.0));
    let (direction, hit) = locate_pixel(&model, &pose, &vehicle(), 50.0, &centre).unwrap();
    assert!(close(direction.global.pitch, -FRAC_PI_2, 1e-12));
    assert!(close(direction.camera.yaw, 0.0, 1e-12));
    assert!(close(direction.camera.pitch, 0.0, 1e-12));
    let hit = hit.unwrap();
    assert!(close(hit.distance_m, 50.0, 1e-9));
    assert!(hit.ned.xy().norm() < 1e-9);
    assert!(close(hit.position.lat_deg, vehicle().lat_deg, 1e-12));
    assert!(close(hit.position.lon_deg, vehicle().lon_deg, 1e-12));
    assert!(close(hit.position.alt_msl_m, 538.0 - 50.0, 1e-9));
}

#[test]
fn edge_of_a_90_degree_pinhole_is_45_degrees() {
    let model = pinhole_90();
    let pose = CameraPose::new(attitude(0.0, 0.0, 30.0), &Mount::forward());
    let right = Direction::of_offset(&model, &pose, Offset { x: 1.0, y: 0.0 }).unwrap();
    assert!(close(right.camera.yaw, FRAC_PI_4, 1e-12));
    assert!(close(right.camera.pitch, 0.0, 1e-12));
    assert!(close(right.heading.yaw, FRAC_PI_4, 1e-12));
    assert!(close(right.global.yaw, 75f64.to_radians(), 1e-12));
    let left = Direction::of_pixel(&model, &pose, &Point2::new(0.0, 540.0)).unwrap();
    assert!(close(left.camera.yaw, -FRAC_PI_4, 1e-12));
    // y = +1 is the top edge: up, atan(540 / 960).
    let top = Direction::of_offset(&model, &pose, Offset { x: 0.0, y: 1.0 }).unwrap();
    assert!(close(top.camera.pitch, (540.0f64 / 960.0).atan(), 1e-12));
    assert!(close(top.global.pitch, (540.0f64 / 960.0).atan(), 1e-12));
}

#[test]
fn global_yaw_wraps_through_south() {
    let model = pinhole_90();
    let pose = CameraPose::new(attitude(0.0, 0.0, 170.0), &Mount::forward());
    let d = Direction::of_offset(&model, &pose, Offset { x: 1.0, y: 0.0 }).unwrap();
    assert!(close(d.global.yaw, (215.0f64 - 360.0).to_radians(), 1e-12));
    assert!(close(d.heading.yaw, FRAC_PI_4, 1e-12));
}

fn assert_round_trips(model: &CameraModel) {
    let mut checked = 0;
    for j in 0..=27 {
        for i in 0..=48 {
            let pixel = Point2::new(f64::from(i) * 40.0, f64::from(j) * 40.0);
            let ray = model
                .pixel_to_ray(&pixel)
                .unwrap_or_else(|| panic!("no ray at {pixel}"));
            let back = model.ray_to_pixel(&ray).unwrap();
            assert!((back - pixel).norm() < 1e-6, "{pixel} → {back}");
            checked += 1;
        }
    }
    assert_eq!(checked, 49 * 28);
}

#[test]
fn pixel_ray_pixel_round_trips_pinhole() {
    assert_round_trips(&pinhole_90());
    assert_round_trips(&distorted_pinhole());
}

#[test]
fn pixel_ray_pixel_round_trips_fisheye() {
    let model = fisheye();
    assert_round_trips(&model);
    // The corner is beyond 90° from the axis: the fisheye sees behind its plane.
    let corner = model.pixel_to_ray(&Point2::new(0.0, 0.0)).unwrap();
    assert!(corner.x < 0.0);
}

#[test]
fn fisheye_is_equidistant() {
    let model = CameraModel::new(
        W,
        H,
        500.0,
        500.0,
        960.0,
        540.0,
        Lens::Fisheye { k: [0.0; 4] },
    )
    .unwrap();
    // 60° to the right of the axis lands at f·θ from the centre.
    let ray = Vector3::new(60f64.to_radians().cos(), 60f64.to_radians().sin(), 0.0);
    let pixel = model.ray_to_pixel(&ray).unwrap();
    assert!(close(pixel.x, 960.0 + 500.0 * PI / 3.0, 1e-9));
    assert!(close(pixel.y, 540.0, 1e-9));
    // Straight back is not imaged; neither is anything behind a pinhole.
    assert!(model.ray_to_pixel(&Vector3::new(-1.0, 0.0, 0.0)).is_none());
    assert!(pinhole_90()
        .ray_to_pixel(&Vector3::new(-1.0, 0.2, 0.0))
        .is_none());
}

#[test]
fn rays_past_the_lens_fold_do_not_project() {
    // Barrel distortion whose radial polynomial folds at r² ≈ 3.7 and rises again
    // past r² ≈ 16.5: a ray at r = 4.5 would otherwise land back inside the image.
    let model = CameraModel::new(
        W,
        H,
        1333.5,
        1334.8,
        967.0,
        535.0,
        Lens::Pinhole {
            k1: -0.111,
            k2: 0.0033,
            p1: 0.0,
            p2: 0.0,
        },
    )
    .unwrap();
    let slope = 1.0 - 3.0 * 0.111 * model.fold + 5.0 * 0.0033 * model.fold.powi(2);
    assert!(close(slope, 0.0, 1e-12) && (3.0..4.0).contains(&model.fold));
    assert!(model.ray_to_pixel(&Vector3::new(1.0, 4.5, 0.0)).is_none());
    assert!(model.ray_to_pixel(&Vector3::new(1.0, 1.5, 0.0)).is_some());
    assert_eq!(radial_fold_r2(0.0, 0.0), f64::INFINITY);
    assert!(close(radial_fold_r2(-0.1, 0.0), 10.0 / 3.0, 1e-12));
    // A fisheye polynomial that peaks: θ past the peak is not imaged, nor is a
    // pixel beyond the polynomial's maximum.
    let k = [-0.1, 0.0, 0.0, 0.0];
    let fold = equidistant_fold(k);
    assert!(close(fold, (1.0f64 / 0.3).sqrt(), 1e-9), "{fold}");
    let fisheye = CameraModel::new(W, H, 500.0, 500.0, 960.0, 540.0, Lens::Fisheye { k }).unwrap();
    let past = Vector3::new((fold + 0.1).cos(), (fold + 0.1).sin(), 0.0);
    assert!(fisheye.ray_to_pixel(&past).is_none());
    let peak = equidistant(fold, k).0;
    assert!(fisheye
        .pixel_to_ray(&Point2::new(960.0 + 500.0 * (peak + 0.01), 540.0))
        .is_none());
}

#[test]
fn ground_target_50m_north_at_50m_height() {
    let model = pinhole_90();
    // Camera pitched 45° down, facing north: the target is on the optical axis.
    let pose = CameraPose::new(
        attitude(0.0, 0.0, 0.0),
        &Mount::from_euler(0.0, -FRAC_PI_4, 0.0),
    );
    let v = vehicle();
    let target = v.offset_by(&Vector3::new(50.0, 0.0, 50.0));
    let pixel = pixel_of_position(&model, &pose, &v, &target).unwrap();
    assert!((pixel - Point2::new(960.0, 540.0)).norm() < 1e-6, "{pixel}");
    // 10 m east of that: camera frame (100/√2, 10, 0) → u = cx + f·10/(100/√2).
    let target_east = v.offset_by(&Vector3::new(50.0, 10.0, 50.0));
    let pixel_east = pixel_of_position(&model, &pose, &v, &target_east).unwrap();
    let expected_u = 960.0 + 960.0 * 10.0 / (100.0 / 2f64.sqrt());
    assert!(close(pixel_east.x, expected_u, 1e-6), "{pixel_east}");
    assert!(close(pixel_east.y, 540.0, 1e-6), "{pixel_east}");

    for (target, pixel) in [(target, pixel), (target_east, pixel_east)] {
        let (direction, hit) = locate_pixel(&model, &pose, &v, 50.0, &pixel).unwrap();
        let hit = hit.unwrap();
        let error = hit.position.ned_to(&target).norm();
        assert!(error < 0.01, "geolocated {error} m off");
        assert!(close(hit.distance_m, v.ned_to(&target).norm(), 0.01));
        let truth = YawPitch::of(&v.ned_to(&target)).unwrap();
        assert!(close(direction.global.yaw, truth.yaw, 1e-9));
        assert!(close(direction.global.pitch, truth.pitch, 1e-9));
    }
    assert!(close(
        locate_pixel(&model, &pose, &v, 50.0, &pixel)
            .unwrap()
            .0
            .global
            .pitch,
        -FRAC_PI_4,
        1e-9
    ));
}

#[test]
fn ground_target_through_a_distorted_fisheye() {
    let model = fisheye();
    let pose = CameraPose::new(
        attitude(0.0, 0.0, 120.0),
        &Mount::from_euler(0.2, -0.9, 0.0),
    );
    let v = vehicle();
    let target = v.offset_by(&Vector3::new(-30.0, 45.0, 50.0));
    let pixel = pixel_of_position(&model, &pose, &v, &target).unwrap();
    assert!(model.contains(&pixel));
    let (_, hit) = locate_pixel(&model, &pose, &v, 50.0, &pixel).unwrap();
    assert!(hit.unwrap().position.ned_to(&target).norm() < 0.01);
}

#[test]
fn vehicle_tilt_is_compensated() {
    let model = distorted_pinhole();
    let v = vehicle();
    let mount = Mount::from_euler(0.0, -0.6, 0.0);
    let target = v.offset_by(&Vector3::new(40.0, 25.0, 60.0));
    let truth = YawPitch::of(&v.ned_to(&target)).unwrap();
    let level = CameraPose::new(attitude(0.0, 0.0, 30.0), &mount);
    let tilted = CameraPose::new(attitude(12.0, -7.0, 30.0), &mount);
    let p_level = pixel_of_position(&model, &level, &v, &target).unwrap();
    let p_tilted = pixel_of_position(&model, &tilted, &v, &target).unwrap();
    // The tilt moves the target in the image...
    assert!((p_level - p_tilted).norm() > 50.0);
    // ...but not in the world.
    for (pose, pixel) in [(level, p_level), (tilted, p_tilted)] {
        let (d, hit) = locate_pixel(&model, &pose, &v, 60.0, &pixel).unwrap();
        assert!(close(d.global.yaw, truth.yaw, 1e-9));
        assert!(close(d.global.pitch, truth.pitch, 1e-9));
        assert!(hit.unwrap().position.ned_to(&target).norm() < 0.01);
    }
    let d_level = Direction::of_pixel(&model, &level, &p_level).unwrap();
    let d_tilted = Direction::of_pixel(&model, &tilted, &p_tilted).unwrap();
    assert!((d_level.camera.yaw - d_tilted.camera.yaw).abs() > 0.01);
}

#[test]
fn no_ground_at_or_above_the_horizon() {
    let v = vehicle();
    assert!(intersect_ground(&v, 50.0, &Vector3::new(1.0, 0.0, 0.0)).is_none());
    assert!(intersect_ground(&v, 50.0, &Vector3::new(1.0, 0.0, -0.1)).is_none());
    assert!(intersect_ground(&v, 50.0, &Vector3::zeros()).is_none());
    // Grazing: 50 m down over > 20 km.
    assert!(intersect_ground(&v, 50.0, &Vector3::new(1.0, 0.0, 0.001)).is_none());
    assert!(intersect_ground(&v, 0.0, &Vector3::new(0.0, 0.0, 1.0)).is_none());
    assert!(intersect_ground(&v, f64::NAN, &Vector3::new(0.0, 0.0, 1.0)).is_none());
    let hit = intersect_ground(&v, 50.0, &Vector3::new(1.0, 0.0, 1.0)).unwrap();
    assert!(close(hit.distance_m, 50.0 * 2f64.sqrt(), 1e-9));
    assert!(close(hit.ned.x, 50.0, 1e-9));
    // A forward camera's upper half looks at the sky.
    let model = pinhole_90();
    let pose = CameraPose::new(attitude(0.0, 0.0, 0.0), &Mount::forward());
    let (d, hit) = locate_pixel(&model, &pose, &v, 50.0, &Point2::new(960.0, 100.0)).unwrap();
    assert!(d.global.pitch > 0.0);
    assert!(hit.is_none());
}

#[test]
fn offsets_and_wire_values() {
    let model = pinhole_90();
    assert_eq!(
        model.offset_to_pixel(Offset { x: -1.0, y: 1.0 }),
        Point2::new(0.0, 0.0)
    );
    assert_eq!(
        model.offset_to_pixel(Offset { x: 1.0, y: -1.0 }),
        Point2::new(W, H)
    );
    assert_eq!(Offset::from_wire(32767, -32767), Offset { x: 1.0, y: -1.0 });
    assert_eq!(Offset::from_wire(i16::MIN, 0), Offset { x: -1.0, y: 0.0 });
    assert_eq!(Offset { x: 0.5, y: -2.0 }.to_wire(), (16384, -32767));
    assert_eq!(
        Offset {
            x: f64::NAN,
            y: 0.0
        }
        .to_wire(),
        (0, 0)
    );
}

#[test]
fn header_models_and_refusals() {
    let mut header = FrameHeader {
        width: 1280,
        height: 720,
        ..FrameHeader::default()
    };
    assert_eq!(
        CameraModel::from_header(&header),
        Err(GeometryError::NoIntrinsics)
    );
    header.intrinsics = CameraIntrinsics {
        fx: 640.0,
        fy: 640.0,
        cx: 640.0,
        cy: 360.0,
        k: [0.0; 4],
        lens_model: LensModel::Pinhole.to_wire(),
        valid: 1,
        reserved: [0; 2],
    };
    let model = CameraModel::from_header(&header).unwrap();
    let right = model.pixel_to_ray(&Point2::new(1280.0, 360.0)).unwrap();
    assert!(close(YawPitch::of(&right).unwrap().yaw, FRAC_PI_4, 1e-12));
    header.intrinsics.lens_model = LensModel::Fisheye.to_wire();
    assert!(matches!(
        CameraModel::from_header(&header).unwrap().lens(),
        Lens::Fisheye { .. }
    ));
    header.intrinsics.lens_model = 9;
    assert_eq!(
        CameraModel::from_header(&header),
        Err(GeometryError::LensModel(9))
    );
    header.intrinsics.lens_model = 0;
    header.intrinsics.fx = 0.0;
    assert!(matches!(
        CameraModel::from_header(&header),
        Err(GeometryError::Intrinsics { .. })
    ));

    assert_eq!(
        CameraPose::from_capture(&header),
        Err(GeometryError::NoPose)
    );
    header.pose.valid = 1;
    assert!(matches!(
        CameraPose::from_capture(&header),
        Err(GeometryError::Attitude(_))
    ));
    header.pose.attitude_q = [1.0, 0.0, 0.0, 0.0];
    header.pose.lat_deg = 47.0;
    header.pose.lon_deg = 8.0;
    header.pose.alt_m = 500.0;
    assert!(CameraPose::from_capture(&header).is_ok());
    assert_eq!(
        GeoPosition::from_capture(&header.pose),
        Ok(GeoPosition {
            lat_deg: 47.0,
            lon_deg: 8.0,
            alt_msl_m: 500.0
        })
    );
    header.pose.lat_deg = f64::NAN;
    assert!(GeoPosition::from_capture(&header.pose).is_err());
}

#[test]
fn wrap_pi_stays_in_range() {
    assert!(close(wrap_pi(3.0 * PI / 2.0), -FRAC_PI_2, 1e-12));
    assert!(close(wrap_pi(-3.0 * PI / 2.0), FRAC_PI_2, 1e-12));
    assert!(close(wrap_pi(PI), -PI, 1e-12));
    assert!(close(wrap_pi(0.1), 0.1, 1e-15));
}

fn any_model() -> impl Strategy<Value = CameraModel> {
    prop_oneof![
        // Pinholes of 65..95° HFOV with distortion a calibration of such a lens
        // gives (monotonic over the whole image).
        (
            -0.12f64..0.05,
            -0.02f64..0.02,
            -0.002f64..0.002,
            -0.002f64..0.002,
            900.0f64..1500.0
        )
            .prop_map(|(k1, k2, p1, p2, f)| CameraModel::new(
                W,
                H,
                f,
                f * 1.001,
                W / 2.0 + 7.0,
                H / 2.0 - 5.0,
                Lens::Pinhole { k1, k2, p1, p2 }
            )
            .unwrap()),
        // Fisheyes of up to ~195° diagonal with coefficients that keep the
        // polynomial increasing over the whole image.
        (
            -0.01f64..0.03,
            -0.002f64..0.002,
            -0.0003f64..0.0003,
            -0.00003f64..0.00003,
            650.0f64..1000.0
        )
            .prop_map(|(k1, k2, k3, k4, f)| CameraModel::new(
                W,
                H,
                f,
                f,
                W / 2.0,
                H / 2.0,
                Lens::Fisheye {
                    k: [k1, k2, k3, k4]
                }
            )
            .unwrap()),
    ]
    // A calibration describes a lens that covers its own image: the distortion
    // stays invertible out to the corners (not every random set of coefficients
    // does).
    .prop_filter("lens covers the image", |m| {
        [(0.0, 0.0), (W, 0.0), (0.0, H), (W, H)]
            .iter()
            .all(|&(u, v)| m.pixel_to_ray(&Point2::new(u, v)).is_some())
    })
}

/// The camera's synthetic scene and this geolocation share one geodesy: every
/// ground point the camera renders at a pixel is geolocated back to where the
/// scene put it, to well under 0.01 % of range (0.17 % when the scene was a sphere
/// of the equatorial radius). What is left comes from the scene being one flat
/// plane at its origin while geolocation works in the vehicle's tangent plane.
#[test]
fn camera_truth_and_geolocation_agree() {
    use skymesh_camera::synthetic::Synthetic;
    use skymesh_ipc_types::VehicleState;
    use skymesh_runtime::ServiceConfig;

    let text =
        skymesh_camera::RawConfig::DEFAULT_TOML.replace("pitch_deg = -90.0", "pitch_deg = -35.0");
    assert!(text.contains("pitch_deg = -35.0"));
    let settings: skymesh_camera::Settings =
        skymesh_runtime::config::parse::<skymesh_camera::RawConfig>(&text, "test").unwrap();
    let k = settings.intrinsics;
    let mut camera = Synthetic::new(settings.clone());
    let state = |lat_deg: f64, lon_deg: f64, alt_rel_m: f32, yaw_deg: f32| VehicleState {
        position_valid: 1,
        attitude_valid: 1,
        lat_deg,
        lon_deg,
        alt_msl_m: 584.0 + alt_rel_m,
        alt_rel_m,
        yaw_rad: yaw_deg.to_radians(),
        attitude_q: [1.0, 0.0, 0.0, 0.0],
        ..VehicleState::default()
    };
    // The first state is the scene's origin; the vehicle then flies 150 m out.
    camera.update_vehicle(&state(-35.363_261, 149.165_230, 0.0, 0.0));
    let height = 60.0;
    camera.update_vehicle(&state(-35.362_1, 149.166_5, height as f32, 40.0));
    let (_, cam, capture, heading) = camera.pose().unwrap();
    let origin = camera.origin().unwrap();
    let mut header = FrameHeader::default();
    header.set_geometry(
        settings.format,
        settings.width,
        settings.height,
        settings.stride(),
    );
    header.intrinsics = k.to_wire();
    header.pose = capture;
    header.vehicle_heading_deg = heading;

    let model = CameraModel::from_header(&header).unwrap();
    let pose = CameraPose::from_capture(&header).unwrap();
    let vehicle = GeoPosition::from_capture(&header.pose).unwrap();
    let (mut worst, mut hits) = (0.0f64, 0);
    for i in 0..=8 {
        for j in 0..=8 {
            let u = f64::from(settings.width - 1) * f64::from(i) / 8.0;
            let v = f64::from(settings.height - 1) * f64::from(j) / 8.0;
            let Some((north, east)) = cam.ground_at(&k, u, v) else {
                continue;
            };
            let (lat_deg, lon_deg) = origin.to_latlon(north, east);
            let truth = GeoPosition {
                lat_deg,
                lon_deg,
                alt_msl_m: origin.ground_alt_msl_m,
            };
            let (_, hit) =
                locate_pixel(&model, &pose, &vehicle, height, &Point2::new(u, v)).unwrap();
            let hit = hit.expect("vision sees the ground the camera rendered");
            worst = worst.max(hit.position.ned_to(&truth).norm() / hit.distance_m);
            hits += 1;
        }
    }
    assert!(hits > 40, "{hits} ground pixels");
    assert!(worst < 2e-5, "{:.5} % of range", worst * 100.0);
}

proptest! {
    #[test]
    fn pixel_ray_pixel(model in any_model(), u in 0.0f64..W, v in 0.0f64..H) {
        let pixel = Point2::new(u, v);
        let ray = model.pixel_to_ray(&pixel).unwrap();
        prop_assert!((ray.norm() - 1.0).abs() < 1e-12);
        let back = model.ray_to_pixel(&ray).unwrap();
        prop_assert!((back - pixel).norm() < 1e-6, "{} → {}", pixel, back);
    }

    #[test]
    fn offset_pixel_offset(x in -1.0f64..1.0, y in -1.0f64..1.0) {
        let model = pinhole_90();
        let offset = model.pixel_to_offset(&model.offset_to_pixel(Offset { x, y }));
        prop_assert!(close(offset.x, x, 1e-12) && close(offset.y, y, 1e-12));
    }

    #[test]
    fn yaw_pitch_direction(yaw in (-PI + 1e-6)..(PI - 1e-6), pitch in (-FRAC_PI_2 + 1e-3)..(FRAC_PI_2 - 1e-3)) {
        let angles = YawPitch::of(&YawPitch { yaw, pitch }.direction()).unwrap();
        prop_assert!(close(angles.yaw, yaw, 1e-9) && close(angles.pitch, pitch, 1e-9));
    }

    #[test]
    fn ground_point_pixel_ground(
        model in any_model(),
        roll in -25.0f64..25.0,
        pitch in -25.0f64..25.0,
        yaw in -180.0f64..180.0,
        mount_pitch in -1.5f64..-0.3,
        north in -200.0f64..200.0,
        east in -200.0f64..200.0,
        height in 5.0f64..150.0,
    ) {
        let v = vehicle();
        let pose = CameraPose::new(attitude(roll, pitch, yaw), &Mount::from_euler(0.0, mount_pitch, 0.0));
        let target = v.offset_by(&Vector3::new(north, east, height));
        if let Some(pixel) = pixel_of_position(&model, &pose, &v, &target) {
            if model.contains(&pixel) {
                let (_, hit) = locate_pixel(&model, &pose, &v, height, &pixel).unwrap();
                let error = hit.unwrap().position.ned_to(&target).norm();
                prop_assert!(error < 1e-3, "{} m off", error);
            }
        }
    }

    #[test]
    fn geodetic_offsets_round_trip(
        lat in -80.0f64..80.0,
        lon in -180.0f64..180.0,
        north in -3000.0f64..3000.0,
        east in -3000.0f64..3000.0,
        down in -500.0f64..500.0,
    ) {
        let origin = GeoPosition { lat_deg: lat, lon_deg: lon, alt_msl_m: 100.0 };
        let ned = Vector3::new(north, east, down);
        let back = origin.ned_to(&origin.offset_by(&ned));
        prop_assert!((back - ned).norm() < 1e-6);
    }
}
