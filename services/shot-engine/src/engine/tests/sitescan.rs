//! Site Scan: inspect (take-off, waypoints, gimbal, body velocities), structure
//! scan and survey, flown on a point mass that follows the setpoints.

use skymesh_ipc_types::shot_api::shots::{NONE, ORBIT};
use skymesh_ipc_types::{AppGeofence, ShotPhase};

use super::*;
use crate::engine::sitescan::{INSPECT, SCAN, SURVEY};

fn m_lon() -> f64 {
    M_LAT / LAT.to_radians().cos()
}

fn error_text(out: &Outputs) -> String {
    out.to_app
        .iter()
        .find_map(|m| match m {
            ShotEvent::Error(t) => Some(t.clone()),
            _ => None,
        })
        .unwrap_or_default()
}

fn count(out: &Outputs, kind: CommandKind) -> usize {
    out.commands
        .iter()
        .filter(|c| c.kind == kind.to_wire())
        .count()
}

impl Harness {
    /// Ticks for `ms`, the vehicle following each velocity setpoint at once; stops
    /// early when the shot ends.
    fn fly(&mut self, ms: u64) -> Outputs {
        let mut all = Outputs::default();
        for _ in 0..ms / 40 {
            let o = self.tick();
            if let Some(Command::VelocityNed { vel_ned_mps, .. }) = cmds(&o)
                .into_iter()
                .rev()
                .find(|c| matches!(c, Command::VelocityNed { .. }))
            {
                self.state.vel_ned_mps = vel_ned_mps;
            }
            let v = self.state.vel_ned_mps;
            self.state.lat_deg += f64::from(v[0]) * 0.04 * M_LAT;
            self.state.lon_deg += f64::from(v[1]) * 0.04 * m_lon();
            self.state.alt_rel_m -= v[2] * 0.04;
            let ended = self.engine.current_shot() == NONE;
            all.commands.extend(o.commands);
            all.to_app.extend(o.to_app);
            if ended {
                break;
            }
        }
        all
    }

    /// On the ground, armed, LOITER.
    fn landed() -> Harness {
        let mut h = Harness::ready();
        h.state.alt_rel_m = 0.0;
        h.push_state();
        h
    }

    fn inspecting(&mut self) {
        self.app(ShotRequest::InspectStart {
            takeoff_alt_m: 30.0,
        });
        self.set_mode(FlightMode::Guided);
        self.tick();
    }
}

#[test]
fn inspect_start_on_the_ground_takes_off_once_guided() {
    let mut h = Harness::landed();
    let out = h.app(ShotRequest::InspectStart {
        takeoff_alt_m: 10.0,
    });
    assert_eq!(
        cmds(&out),
        [
            Command::GrabFlightAuthority,
            Command::SetMode(FlightMode::Guided)
        ]
    );
    assert!(out.to_app.is_empty(), "no shot index for the app");
    assert_eq!(h.engine.current_shot(), INSPECT);
    let st = h.engine.status();
    assert_eq!((st.shot, st.phase()), (INSPECT as i8, ShotPhase::Running));
    assert_eq!(
        h.counter("skymesh_shot_entered_total", &[("shot", "inspect")]),
        1
    );
    // Not GUIDED yet: nothing, and no velocity setpoints ever.
    assert!(h.run(200).commands.is_empty());
    h.set_mode(FlightMode::Guided);
    let out = h.tick();
    assert_eq!(cmds(&out), [Command::Takeoff { alt_rel_m: 10.0 }]);
    let out = h.run(500);
    assert!(out.commands.is_empty());
}

#[test]
fn inspect_start_in_the_air_climbs_straight_up() {
    let mut h = Harness::ready();
    h.app(ShotRequest::InspectStart {
        takeoff_alt_m: 35.0,
    });
    h.set_mode(FlightMode::Guided);
    assert_eq!(
        cmds(&h.tick()),
        [Command::GoTo {
            lat_deg: LAT,
            lon_deg: LON,
            alt_rel_m: 35.0,
            yaw_deg: None,
            speed_mps: Some(6.0)
        }]
    );
}

#[test]
fn inspect_start_is_gated_checked_and_once() {
    let mut h = Harness::landed();
    h.status.armed = 0;
    h.push_status();
    let out = h.app(ShotRequest::InspectStart {
        takeoff_alt_m: 10.0,
    });
    assert_eq!(out.to_app, [ShotEvent::Refused(1)]);
    assert!(out.commands.is_empty());
    assert_eq!(h.engine.current_shot(), NONE);

    let mut h = Harness::ready();
    for alt in [0.5, 500.0] {
        let out = h.app(ShotRequest::InspectStart { takeoff_alt_m: alt });
        assert!(error_text(&out).contains("outside 1..=120 m"), "{out:?}");
        assert!(out.commands.is_empty());
    }
    h.inspecting();
    let out = h.app(ShotRequest::InspectStart {
        takeoff_alt_m: 50.0,
    });
    assert!(out.commands.is_empty() && out.to_app.is_empty());
}

#[test]
fn inspect_flies_waypoints_gimbal_and_body_velocities() {
    let mut h = Harness::ready();
    h.inspecting();
    let out = h.app(ShotRequest::InspectSetWaypoint {
        lat_deg: -35.3625,
        lon_deg: 149.1655,
        alt_m: 25.0,
    });
    assert_eq!(
        cmds(&out),
        [Command::GoTo {
            lat_deg: f64::from(-35.3625f32),
            lon_deg: f64::from(149.1655f32),
            alt_rel_m: 25.0,
            yaw_deg: None,
            speed_mps: Some(6.0)
        }]
    );
    let out = h.app(ShotRequest::InspectMoveGimbal {
        pitch_deg: -120.0,
        roll_deg: 5.0,
        yaw_deg: 370.0,
    });
    assert_eq!(
        cmds(&out),
        [
            Command::Gimbal {
                pitch_deg: -90.0,
                yaw_deg: 0.0
            },
            Command::SetYaw {
                yaw_deg: 10.0,
                rate_dps: 0.0,
                relative: false
            }
        ]
    );
    // Heading east: forward is east, right is south.
    let out = h.app(ShotRequest::InspectMoveVehicle {
        vx: 2.0,
        vy: 1.0,
        vz: -0.5,
    });
    let c = out.commands[0];
    assert_eq!(
        c.max_age_ms, 500,
        "a setpoint: the arbiter brakes when they stop"
    );
    let Command::VelocityNed { vel_ned_mps, .. } = c.command().unwrap() else {
        panic!("{c:?}");
    };
    for (got, want) in vel_ned_mps.iter().zip([-1.0, 2.0, -0.5]) {
        assert!((got - want).abs() < 1e-5, "{vel_ned_mps:?}");
    }
    // Too fast: within the limits.
    let out = h.app(ShotRequest::InspectMoveVehicle {
        vx: 20.0,
        vy: 0.0,
        vz: 5.0,
    });
    let Some(Command::VelocityNed { vel_ned_mps, .. }) = cmds(&out).pop() else {
        panic!();
    };
    assert!((vel_ned_mps[1] - 6.0).abs() < 1e-4 && vel_ned_mps[2] == 1.5);
    // Between messages the engine sends no setpoint.
    assert_eq!(count(&h.run(600), CommandKind::VelocityNed), 0);
}

#[test]
fn inspect_commands_wait_for_guided_and_velocities_need_it() {
    let mut h = Harness::ready();
    h.app(ShotRequest::InspectStart {
        takeoff_alt_m: 30.0,
    });
    let out = h.app(ShotRequest::InspectSetWaypoint {
        lat_deg: -35.3625,
        lon_deg: 149.1655,
        alt_m: 25.0,
    });
    assert!(out.commands.is_empty());
    let out = h.app(ShotRequest::InspectMoveVehicle {
        vx: 1.0,
        vy: 0.0,
        vz: 0.0,
    });
    assert!(out.commands.is_empty(), "dropped, not queued");
    h.set_mode(FlightMode::Guided);
    let out = h.tick();
    assert_eq!(kinds(&out), [CommandKind::GoTo, CommandKind::GoTo]);
    let alts: Vec<f32> = cmds(&out)
        .iter()
        .map(|c| match c {
            Command::GoTo { alt_rel_m, .. } => *alt_rel_m,
            _ => 0.0,
        })
        .collect();
    assert_eq!(alts, [30.0, 25.0], "the climb, then the waypoint");
}

#[test]
fn inspect_commands_outside_inspect_are_refused_and_bad_altitudes_too() {
    let mut h = Harness::ready();
    let out = h.app(ShotRequest::InspectSetWaypoint {
        lat_deg: -35.3625,
        lon_deg: 149.1655,
        alt_m: 25.0,
    });
    assert!(error_text(&out).contains("needs an inspect shot"));
    let out = h.app(ShotRequest::InspectMoveGimbal {
        pitch_deg: -10.0,
        roll_deg: 0.0,
        yaw_deg: 0.0,
    });
    assert!(error_text(&out).contains("needs an inspect shot"));
    let out = h.app(ShotRequest::InspectMoveVehicle {
        vx: 1.0,
        vy: 0.0,
        vz: 0.0,
    });
    assert!(out.to_app.is_empty() && out.commands.is_empty());

    h.inspecting();
    let out = h.app(ShotRequest::InspectSetWaypoint {
        lat_deg: -35.3625,
        lon_deg: 149.1655,
        alt_m: 300.0,
    });
    assert!(error_text(&out).contains("waypoint altitude 300 m"));
    assert!(out.commands.is_empty());
}

#[test]
fn an_idle_inspect_keeps_its_authority() {
    let mut h = Harness::ready();
    h.inspecting();
    let out = h.run(2_400);
    assert_eq!(kinds(&out), [CommandKind::GrabFlightAuthority; 2]);
}

#[test]
fn inspect_ends_with_the_app_in_loiter() {
    let mut h = Harness::ready();
    h.inspecting();
    let out = h.session(1, false);
    assert_eq!(h.engine.last_exit(), "app_disconnected");
    assert_eq!(
        kinds(&out),
        [
            CommandKind::Brake,
            CommandKind::SetMode,
            CommandKind::ReleaseFlightAuthority
        ]
    );
}

#[test]
fn scan_circles_the_orbit_roi_level_by_level_with_photos_then_loiters() {
    let mut h = Harness::ready();
    h.engine.settings.site_scan.scan_speed_mps = 6.0;
    h.orbiting();
    let out = h.app(ShotRequest::ScanStart);
    // The orbit hands over (LOITER), the scan takes the vehicle (GUIDED again).
    assert_eq!(out.to_app, [ShotEvent::CurrentShot(NONE)]);
    assert_eq!(h.engine.last_exit(), "");
    assert_eq!(h.engine.current_shot(), SCAN);
    let st = h.engine.status();
    assert_eq!(st.roi_valid, 1);
    assert!(
        ((st.roi_lat_deg - LAT) / M_LAT - 30.0).abs() < 1e-6,
        "the orbit's ROI"
    );
    // The LOITER of the hand-over must not end it; GUIDED again does count.
    h.set_mode(FlightMode::Loiter);
    assert_eq!(h.engine.current_shot(), SCAN);
    h.set_mode(FlightMode::Guided);
    let out = h.fly(400_000);
    assert_eq!(h.engine.last_exit(), "finished");
    // 20, 15, 10, 5 m: four turns of 188 m, a photo every 32.9 m from the start.
    let photos = count(&out, CommandKind::CameraCapture);
    assert!((24..=28).contains(&photos), "{photos}");
    assert!(h.state.alt_rel_m < 6.0, "{}", h.state.alt_rel_m);
    // The camera on the structure, then handed back in LOITER.
    assert!(count(&out, CommandKind::SetRoi) >= 4);
    let tail = kinds(&out);
    assert_eq!(
        tail[tail.len() - 5..],
        [
            CommandKind::Brake,
            CommandKind::SetMode,
            CommandKind::ClearRoi,
            CommandKind::ReleaseFlightAuthority,
            CommandKind::ReleasePayloadAuthority
        ]
    );
    assert_eq!(out.to_app.last(), Some(&ShotEvent::CurrentShot(NONE)));
}

#[test]
fn scan_reports_progress_and_pauses() {
    let mut h = Harness::ready();
    h.engine.settings.site_scan.scan_center = Some(crate::shots::GeoPoint {
        lat_deg: LAT,
        lon_deg: LON + 25.0 * m_lon(),
        alt_rel_m: 0.0,
    });
    h.app(ShotRequest::ScanStart);
    let st = h.engine.status();
    assert!(
        (st.roi_lon_deg - LON - 25.0 * m_lon()).abs() < 1e-9,
        "the configured centre"
    );
    h.set_mode(FlightMode::Guided);
    h.fly(30_000);
    let p = h.engine.status().progress;
    assert!(p > 0.05 && p < 1.0, "{p}");
    h.app(ShotRequest::Pause);
    assert_eq!(h.engine.status().phase(), ShotPhase::Paused);
    h.fly(10_000);
    let held = h.engine.status().progress;
    h.fly(10_000);
    let now = h.engine.status().progress;
    assert!(
        (now - held).abs() < 1e-3,
        "paused: no progress ({held} → {now})"
    );
}

#[test]
fn scan_without_an_roi_looks_where_the_camera_looks() {
    let mut h = Harness::ready();
    h.app(ShotRequest::ScanStart);
    // Camera level, heading east: 20 m ahead (the test's metres are spherical).
    let st = h.engine.status();
    assert!(
        ((st.roi_lon_deg - LON) / m_lon() - 20.0).abs() < 0.2,
        "{st:?}"
    );
    assert!((st.roi_lat_deg - LAT).abs() < 1e-9);
    // Once only.
    let out = h.app(ShotRequest::ScanStart);
    assert!(out.commands.is_empty() && out.to_app.is_empty());
}

#[test]
fn scan_and_survey_need_the_air() {
    for msg in [ShotRequest::ScanStart, ShotRequest::SurveyStart] {
        let mut h = Harness::landed();
        h.engine.settings.site_scan.survey_area = vec![
            crate::shots::GeoPoint {
                lat_deg: LAT,
                lon_deg: LON,
                alt_rel_m: 0.0,
            },
            crate::shots::GeoPoint {
                lat_deg: LAT + 50.0 * M_LAT,
                lon_deg: LON,
                alt_rel_m: 0.0,
            },
            crate::shots::GeoPoint {
                lat_deg: LAT,
                lon_deg: LON + 50.0 * m_lon(),
                alt_rel_m: 0.0,
            },
        ];
        let out = h.app(msg);
        assert!(error_text(&out).ends_with("take off first (the vehicle is on the ground)"));
        assert_eq!(h.engine.current_shot(), NONE);
        assert_eq!(
            h.counter(
                "skymesh_shot_entry_refusals_total",
                &[("error", "on_ground")]
            ),
            1
        );
    }
}

#[test]
fn survey_without_an_area_is_refused() {
    let mut h = Harness::ready();
    let out = h.app(ShotRequest::SurveyStart);
    assert!(error_text(&out).starts_with("survey: no area to survey"));
    assert!(out.commands.is_empty());
}

#[test]
fn survey_mows_the_keep_in_hold_line_with_photos_then_loiters() {
    let mut h = Harness::ready();
    let rect = |half: f64| {
        [(-1.0, -1.0), (-1.0, 1.0), (1.0, 1.0), (1.0, -1.0)]
            .map(|(n, e)| [LAT + n * half * M_LAT, LON + e * half * m_lon()])
    };
    let (fence, hold) = (rect(60.0), rect(50.0));
    let g = AppGeofence::new(1, [(0u8, &fence[..], &hold[..])].into_iter()).unwrap();
    h.engine.handle_app_geofence(&g, h.now);
    h.drain();
    let out = h.app(ShotRequest::SurveyStart);
    assert_eq!(h.engine.current_shot(), SURVEY);
    assert_eq!(
        kinds(&out)[..2],
        [CommandKind::GrabFlightAuthority, CommandKind::SetMode]
    );
    h.set_mode(FlightMode::Guided);
    let out = h.fly(600_000);
    assert_eq!(h.engine.last_exit(), "finished", "not stopped by the fence");
    assert_eq!(h.counter("skymesh_shot_geofence_activations_total", &[]), 0);
    // 100 m square at 30 m: three lanes 38 m apart, a photo every 16 m.
    let photos = count(&out, CommandKind::CameraCapture);
    assert!((18..=24).contains(&photos), "{photos}");
    assert!(cmds(&out).contains(&Command::Gimbal {
        pitch_deg: -90.0,
        yaw_deg: 0.0
    }));
    assert!((h.state.alt_rel_m - 30.0).abs() < 1.0);
    assert_eq!(
        kinds(&out)[kinds(&out).len() - 4..],
        [
            CommandKind::Brake,
            CommandKind::SetMode,
            CommandKind::ReleaseFlightAuthority,
            CommandKind::ReleasePayloadAuthority
        ]
    );
}

#[test]
fn survey_uses_the_configured_area_without_a_fence_and_survives_the_app() {
    let mut h = Harness::ready();
    h.engine.settings.site_scan.survey_area = [(0.0, 0.0), (80.0, 0.0), (80.0, 80.0), (0.0, 80.0)]
        .iter()
        .map(|(n, e)| crate::shots::GeoPoint {
            lat_deg: LAT + n * M_LAT,
            lon_deg: LON + e * m_lon(),
            alt_rel_m: 0.0,
        })
        .collect();
    h.app(ShotRequest::SurveyStart);
    h.set_mode(FlightMode::Guided);
    h.fly(5_000);
    h.session(1, false);
    assert_eq!(h.engine.current_shot(), SURVEY, "flies on without the app");
    // Another shot replaces it.
    h.connect_app(2);
    h.app(ShotRequest::StartShot(ORBIT));
    assert_eq!(h.engine.current_shot(), ORBIT);
    assert_eq!(
        h.counter("skymesh_shot_exits_total", &[("reason", "replaced")]),
        1
    );
}
