use nalgebra::{Vector2, Vector3};

use super::*;
use crate::shots::fence::{contains, nearest_on_ring};
use crate::shots::sitescan::{
    body_to_ned, photo_spacing_m, ScanConfig, SiteScanError, StructureScan, Survey, SurveyConfig,
};

const SCAN: ScanConfig = ScanConfig {
    radius_m: None,
    altitude_step_m: 5.0,
    min_altitude_m: 8.0,
    overlap: 0.5,
    hfov_deg: 60.0,
};

#[test]
fn body_velocity_turns_with_the_heading() {
    let close = |a: [f32; 3], b: [f32; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5);
    assert!(close(body_to_ned(2.0, 0.0, -1.0, 0.0), [2.0, 0.0, -1.0]));
    assert!(close(body_to_ned(2.0, 0.0, 0.5, 90.0), [0.0, 2.0, 0.5]));
    assert!(close(body_to_ned(0.0, 1.0, 0.0, 90.0), [-1.0, 0.0, 0.0]));
    assert!(close(body_to_ned(1.0, 1.0, 0.0, 180.0), [-1.0, -1.0, 0.0]));
    assert!(close(body_to_ned(1.0, 0.0, 0.0, f32::NAN), [1.0, 0.0, 0.0]));
    // 60° field of view 30 m away at 50 % overlap: 2·30·tan 30°·0.5 = 17.32 m.
    assert!((photo_spacing_m(30.0, 60.0, 0.5) - 17.3205).abs() < 1e-3);
}

#[test]
fn structure_scan_circles_at_descending_levels_with_spaced_photos() {
    let center = Vector3::new(30.0, 0.0, 0.0);
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(0.0, 0.0, -20.0), dynamics);
        let mut scan =
            StructureScan::new(m.to_geo(center), &m.view(), &SCAN).expect("a good config");
        assert_eq!(scan.levels(), &[20.0, 15.0, 10.0]);
        assert!((scan.radius_m() - 30.0).abs() < 1e-3);
        let spacing = f64::from(scan.trigger_spacing_m());
        assert!((spacing - photo_spacing_m(30.0, 60.0, 0.5)).abs() < 1e-3);
        // Photos per level: one per spacing around the circle.
        let per_level = (std::f64::consts::TAU * 30.0 / spacing).ceil() as usize;
        let mut photos: Vec<(usize, Vector3<f64>)> = Vec::new();
        let mut progress = 0.0;
        let mut done = false;
        for _ in 0..ticks(400.0) {
            let s = scan.step(&m.view(), DT, 5.0, &LIMITS);
            let roi = s.guidance.roi.map(|r| m.ned(&r));
            let level = scan.level();
            let alt = f64::from(scan.levels()[level]);
            assert!(
                roi.is_some_and(|r| (r - Vector3::new(30.0, 0.0, -alt)).norm() < 1e-3),
                "camera on the centre at the level's altitude: {roi:?}"
            );
            assert!(s.progress >= progress);
            progress = s.progress;
            if s.trigger {
                photos.push((level, m.ned(&m.view().position)));
            }
            m.fly(&s.guidance);
            if s.done {
                done = true;
                break;
            }
        }
        assert!(done, "{dynamics:?}: {progress}");
        assert_eq!(progress, 1.0);
        for level in 0..3 {
            let at: Vec<Vector3<f64>> = photos
                .iter()
                .filter(|p| p.0 == level)
                .map(|p| p.1)
                .collect();
            assert_eq!(at.len(), per_level, "{dynamics:?} level {level}");
            let alt = f64::from(scan.levels()[level]);
            for p in &at {
                assert!((-p.z - alt).abs() < 1.0, "{dynamics:?}: {p:?} at {alt}");
                let r = ground(p, &center);
                assert!((r - 30.0).abs() < 1.0, "{dynamics:?}: radius {r}");
            }
            // Neighbouring photos a spacing apart along the circle.
            for w in at.windows(2) {
                let chord = ground(&w[0], &w[1]);
                let arc = 2.0 * 30.0 * (chord / 60.0).asin();
                assert!(
                    (arc - spacing).abs() < 0.6,
                    "{dynamics:?}: {arc} vs {spacing}"
                );
            }
        }
    }
}

#[test]
fn scan_pauses_on_the_circle_and_refuses_bad_configs() {
    let center = Vector3::new(0.0, 20.0, 0.0);
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -15.0), DYNAMICS[1]);
    let cfg = ScanConfig {
        radius_m: Some(10.0),
        ..SCAN
    };
    let mut scan = StructureScan::new(m.to_geo(center), &m.view(), &cfg).expect("good");
    assert_eq!(scan.levels(), &[15.0, 10.0]);
    for _ in 0..ticks(8.0) {
        let s = scan.step(&m.view(), DT, -4.0, &LIMITS);
        m.fly(&s.guidance);
    }
    assert!((ground(&m.pos, &center) - 10.0).abs() < 0.5);
    let progress = scan.progress();
    for _ in 0..ticks(5.0) {
        let s = scan.step(&m.view(), DT, 0.0, &LIMITS);
        m.fly(&s.guidance);
    }
    let held = m.pos;
    for _ in 0..ticks(10.0) {
        let s = scan.step(&m.view(), DT, 0.0, &LIMITS);
        assert!(!s.trigger);
        m.fly(&s.guidance);
    }
    assert!((m.pos - held).norm() < 0.1);
    assert!(scan.progress() - progress < 0.1);
    let v = m.view();
    let c = m.to_geo(center);
    for bad in [
        ScanConfig {
            radius_m: Some(1.0),
            ..SCAN
        },
        ScanConfig {
            altitude_step_m: 0.0,
            ..SCAN
        },
        ScanConfig {
            overlap: 1.0,
            ..SCAN
        },
        ScanConfig {
            hfov_deg: f32::NAN,
            ..SCAN
        },
        ScanConfig {
            min_altitude_m: -1e9,
            altitude_step_m: 0.01,
            ..SCAN
        },
    ] {
        assert!(StructureScan::new(c, &v, &bad).is_err(), "{bad:?}");
    }
    // Too close to the centre: the smallest radius.
    let near = PointMass::new(Vector3::new(0.0, 19.0, -15.0), DYNAMICS[0]);
    let s = StructureScan::new(c, &near.view(), &SCAN).expect("good");
    assert_eq!(s.radius_m(), crate::shots::sitescan::MIN_SCAN_RADIUS_M);
}

const SURVEY: SurveyConfig = SurveyConfig {
    altitude_m: 30.0,
    overlap: 0.7,
    sidelap: 0.6,
    hfov_deg: 70.0,
    vfov_deg: 55.0,
    heading_deg: None,
};

/// The polygon as geo points around home, and NE metres.
fn polygon(m: &PointMass, ne: &[(f64, f64)]) -> (Vec<GeoPoint>, Vec<Vector2<f64>>) {
    let geo = ne
        .iter()
        .map(|&(n, e)| m.to_geo(Vector3::new(n, e, 0.0)))
        .collect();
    let pts = ne.iter().map(|&(n, e)| Vector2::new(n, e)).collect();
    (geo, pts)
}

/// Every grid point inside the polygon within spacing/2 of a lane; every lane
/// within the polygon's strip (its ends are on or near the polygon).
fn check_coverage(m: &PointMass, survey: &Survey, ring: &[Vector2<f64>]) {
    let half = f64::from(survey.lane_spacing_m()) / 2.0;
    let lanes: Vec<(Vector2<f64>, Vector2<f64>)> = survey
        .lanes()
        .iter()
        .map(|l| {
            let (a, b) = (m.ned(&l.start), m.ned(&l.end));
            assert!((a.z + 30.0).abs() < 1e-3 && (b.z + 30.0).abs() < 1e-3);
            (a.xy(), b.xy())
        })
        .collect();
    let (min, max) = ring.iter().fold(
        (
            Vector2::repeat(f64::INFINITY),
            Vector2::repeat(f64::NEG_INFINITY),
        ),
        |(lo, hi), p| (lo.inf(p), hi.sup(p)),
    );
    let mut inside = 0;
    let mut x = min.x;
    while x <= max.x {
        let mut y = min.y;
        while y <= max.y {
            let p = Vector2::new(x, y);
            if contains(ring, &p) {
                inside += 1;
                let d = lanes
                    .iter()
                    .map(|(a, b)| {
                        let ab = b - a;
                        let t = ((p - a).dot(&ab) / ab.norm_squared().max(1e-12)).clamp(0.0, 1.0);
                        (a + ab * t - p).norm()
                    })
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    d <= half + 1e-6,
                    "{p:?} is {d} m from every lane (> {half})"
                );
            }
            y += 1.0;
        }
        x += 1.0;
    }
    assert!(inside > 100);
}

#[test]
fn survey_lanes_cover_convex_and_concave_polygons() {
    let m = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    // A slanted quadrilateral, lanes along its longest edge.
    let (geo, ring) = polygon(
        &m,
        &[(0.0, 0.0), (20.0, 120.0), (90.0, 100.0), (70.0, -10.0)],
    );
    let survey = Survey::new(&geo, &SURVEY).expect("a good polygon");
    let spacing = photo_spacing_m(30.0, 70.0, 0.6);
    assert!((f64::from(survey.lane_spacing_m()) - spacing).abs() < 1e-3);
    assert!(
        (f64::from(survey.trigger_spacing_m()) - photo_spacing_m(30.0, 55.0, 0.7)).abs() < 1e-3
    );
    check_coverage(&m, &survey, &ring);
    // Lanes stay within spacing/2 of the polygon (they reach past slanted edges).
    let outside = |p: &Vector2<f64>| {
        if contains(&ring, p) {
            0.0
        } else {
            (nearest_on_ring(&ring, p) - p).norm()
        }
    };
    let mut overhang = 0.0_f64;
    for l in survey.lanes() {
        let (a, b) = (m.ned(&l.start).xy(), m.ned(&l.end).xy());
        for i in 0..=20 {
            overhang = overhang.max(outside(&(a + (b - a) * (f64::from(i) / 20.0))));
        }
    }
    assert!(overhang > 0.5, "slanted edges: {overhang}");
    assert!(overhang <= spacing / 2.0 + 1e-6, "{overhang}");
    // Kept within: every lane inside, its ends on the edge; still spacing apart.
    let within = Survey::new_within(&geo, &SURVEY).expect("a good polygon");
    assert_eq!(within.lanes().len(), survey.lanes().len());
    for l in within.lanes() {
        let (a, b) = (m.ned(&l.start).xy(), m.ned(&l.end).xy());
        for e in [a, b] {
            assert!((nearest_on_ring(&ring, &e) - e).norm() < 1e-6, "{e:?}");
        }
        for i in 1..20 {
            assert!(contains(&ring, &(a + (b - a) * (f64::from(i) / 20.0))));
        }
    }
    // Convex: no lane split; flown boustrophedon (each lane reversed from the last).
    let dirs: Vec<Vector2<f64>> = survey
        .lanes()
        .iter()
        .map(|l| (m.ned(&l.end) - m.ned(&l.start)).xy().normalize())
        .collect();
    assert!(dirs.windows(2).all(|w| w[0].dot(&w[1]) < -0.99), "{dirs:?}");
    // A U open to the north: lanes east-west cross both arms and are split there.
    let u = [
        (0.0, 0.0),
        (0.0, 100.0),
        (80.0, 100.0),
        (80.0, 70.0),
        (20.0, 70.0),
        (20.0, 30.0),
        (80.0, 30.0),
        (80.0, 0.0),
    ];
    let (geo, ring) = polygon(&m, &u);
    let cfg = SurveyConfig {
        heading_deg: Some(90.0),
        ..SURVEY
    };
    let survey = Survey::new(&geo, &cfg).expect("a good polygon");
    check_coverage(&m, &survey, &ring);
    // The rows whose strip lies within the arms (north of 31.6 m) are split in two;
    // the lower rows also cover the base, so they run across the notch.
    let arms: Vec<_> = survey
        .lanes()
        .iter()
        .filter(|l| m.ned(&l.start).x > 35.0)
        .collect();
    assert_eq!(arms.len(), 6, "{:?}", survey.lanes());
    for l in arms {
        let mid = ((m.ned(&l.start) + m.ned(&l.end)) / 2.0).xy();
        assert!(contains(&ring, &mid), "{mid:?} crosses the notch");
    }
    // Kept within the U: no lane crosses the notch.
    let within = Survey::new_within(&geo, &cfg).expect("good");
    for l in within.lanes() {
        let mid = ((m.ned(&l.start) + m.ned(&l.end)) / 2.0).xy();
        assert!(contains(&ring, &mid), "{mid:?} crosses the notch");
    }
    assert_eq!(within.lanes().len(), 2 * 5 - 1, "the base row is whole");
    // A survey heading north-south over the same U: no split needed.
    let survey = Survey::new(
        &geo,
        &SurveyConfig {
            heading_deg: Some(0.0),
            ..SURVEY
        },
    )
    .expect("good");
    check_coverage(&m, &survey, &ring);
}

#[test]
fn a_survey_within_a_rectangle_along_its_sides_still_covers_it() {
    let m = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    let (geo, ring) = polygon(&m, &[(0.0, 0.0), (0.0, 90.0), (50.0, 90.0), (50.0, 0.0)]);
    let survey = Survey::new_within(&geo, &SURVEY).expect("good");
    // Lanes along the longest (east-west) edge.
    for l in survey.lanes() {
        assert!((m.ned(&l.start).x - m.ned(&l.end).x).abs() < 1e-6);
    }
    check_coverage(&m, &survey, &ring);
}

#[test]
fn survey_refuses_what_it_cannot_fly() {
    let m = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    let (square, _) = polygon(&m, &[(0.0, 0.0), (0.0, 50.0), (50.0, 50.0), (50.0, 0.0)]);
    let (bow, _) = polygon(&m, &[(0.0, 0.0), (50.0, 50.0), (0.0, 50.0), (50.0, 0.0)]);
    let (line, _) = polygon(&m, &[(0.0, 0.0), (10.0, 10.0), (20.0, 20.0)]);
    assert!(matches!(
        Survey::new(&square[..2], &SURVEY),
        Err(SiteScanError::TooFewVertices(2))
    ));
    assert_eq!(
        Survey::new(&bow, &SURVEY).err(),
        Some(SiteScanError::BadPolygon)
    );
    assert_eq!(
        Survey::new(&line, &SURVEY).err(),
        Some(SiteScanError::BadPolygon)
    );
    let mut nan = square.clone();
    nan[1].lat_deg = f64::NAN;
    assert_eq!(
        Survey::new(&nan, &SURVEY).err(),
        Some(SiteScanError::BadCoordinate)
    );
    for bad in [
        SurveyConfig {
            altitude_m: 0.0,
            ..SURVEY
        },
        SurveyConfig {
            sidelap: -0.1,
            ..SURVEY
        },
        SurveyConfig {
            vfov_deg: 180.0,
            ..SURVEY
        },
    ] {
        assert!(
            matches!(
                Survey::new(&square, &bad),
                Err(SiteScanError::Config { .. })
            ),
            "{bad:?}"
        );
    }
    // A huge area at a tiny spacing: refused, not allocated.
    let (huge, _) = polygon(&m, &[(0.0, 0.0), (0.0, 5e4), (5e4, 5e4), (5e4, 0.0)]);
    let tiny = SurveyConfig {
        altitude_m: 2.0,
        sidelap: 0.95,
        ..SURVEY
    };
    assert!(matches!(
        Survey::new(&huge, &tiny),
        Err(SiteScanError::TooLarge { .. })
    ));
}

#[test]
fn survey_flies_every_lane_with_photos_at_the_spacing() {
    let m0 = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    let (geo, _) = polygon(
        &m0,
        &[
            (0.0, 0.0),
            (0.0, 60.0),
            (30.0, 60.0),
            (40.0, 30.0),
            (30.0, 0.0),
        ],
    );
    let cfg = SurveyConfig {
        heading_deg: Some(90.0),
        ..SURVEY
    };
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(-10.0, -10.0, -10.0), dynamics);
        let mut survey = Survey::new(&geo, &cfg).expect("good");
        let lanes: Vec<(Vector3<f64>, Vector3<f64>)> = survey
            .lanes()
            .iter()
            .map(|l| (m.ned(&l.start), m.ned(&l.end)))
            .collect();
        let spacing = f64::from(survey.trigger_spacing_m());
        let mut photos = Vec::new();
        let mut progress = 0.0;
        let mut done = false;
        for _ in 0..ticks(300.0) {
            let s = survey.step(&m.view(), DT, 5.0, &LIMITS);
            assert_eq!(s.guidance.gimbal_pitch_deg, Some(-90.0));
            assert!(s.progress >= progress);
            progress = s.progress;
            if s.trigger {
                photos.push(m.ned(&m.view().position));
            }
            m.fly(&s.guidance);
            if s.done {
                done = true;
                break;
            }
        }
        assert!(done, "{dynamics:?}: {progress}");
        // Every photo on a lane at the survey altitude; each lane photographed from
        // end to end at about the spacing.
        for (a, b) in &lanes {
            let on: Vec<f64> = photos
                .iter()
                .filter(|p| {
                    let u = (b - a).normalize();
                    let along = (*p - a).dot(&u);
                    (*p - a - u * along).norm() < 1.0
                        && (-0.6..=(b - a).norm() + 0.6).contains(&along)
                })
                .map(|p| (p - a).norm())
                .collect();
            assert!(!on.is_empty(), "{dynamics:?}: a lane without photos");
            assert!(on[0] < 1.5, "{dynamics:?}: first photo at {}", on[0]);
            let len = (b - a).norm();
            assert!(len - on[on.len() - 1] <= spacing / 2.0 + 0.6);
            for w in on.windows(2) {
                assert!(
                    w[1] - w[0] <= spacing + 0.6 && w[1] - w[0] > 0.0,
                    "{dynamics:?}: {w:?} vs {spacing}"
                );
            }
        }
        for p in &photos {
            assert!((p.z + 30.0).abs() < 0.5, "{dynamics:?}: {p:?}");
        }
        // Holds at the end of the last lane.
        let end = lanes[lanes.len() - 1].1;
        for _ in 0..ticks(5.0) {
            let s = survey.step(&m.view(), DT, 5.0, &LIMITS);
            m.fly(&s.guidance);
        }
        assert!((m.pos - end).norm() < 0.5, "{dynamics:?}");
    }
}
