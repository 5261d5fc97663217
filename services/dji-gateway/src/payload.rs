//! Payload methods → bus commands (pure). The checks every payload method shares
//! (payload_index, payload authority) are in `dispatch`; this module maps one
//! checked request to the `Command`s that carry it out, or says why it cannot be.
//!
//! | method | commands |
//! |---|---|
//! | camera_mode_switch | 0 → `CameraMode Image`, 1 → `CameraMode Video`, 3 (panorama) → `CameraMode Image` and the gateway's panorama mode (remembered once acknowledged; 0/1 leave it); 2 (low light) unsupported |
//! | camera_photo_take / camera_photo_stop | `CameraCapture` / `CameraCaptureStop`; in panorama mode a panorama, swept by the shot engine ([`crate::pano`]; photo_stop ends a running one) |
//! | camera_recording_start / _stop | `RecordStart` / `RecordStop` |
//! | camera_screen_drag | `GimbalRate` (pitch, yaw); locked: the gimbal only pitches and the aircraft turns (`SetYaw` relative, yaw_speed × [`DRAG_STEP_S`]) |
//! | camera_aim | pinhole angles from hfov/vfov → `Gimbal` = current gimbal + offset; locked: `Gimbal` pitch and the aircraft yaws by the offset |
//! | camera_focal_length_set | `CameraZoom Range` (factor − 2)/(zoom_max − 2) × 100 %; above zoom_max out of range; ir unsupported |
//! | gimbal_reset | 0 → (0, 0), 1 → (−90, 0), 2 → (pitch, 0), 3 → (−90, yaw) |
//! | camera_look_at | `SetRoi` (height → above home; a flight command: the nose turns too); the next gimbal method sends `ClearRoi` first |
//! | camera_focus_mode_set | MF → `CameraFocus Range` at the last manual value (50 % until one is set), AFS → `AutoSingle`, AFC → `AutoContinuous` |
//! | camera_focus_value_set | `CameraFocus Range` value (0..=100 %, else out of range) |
//! | screen split, storage, exposure, spot focus, IR metering | no MAVLink equivalent: unsupported |

use dji_proto::{codes, CameraMode, CameraType, ServiceRequest};
use skymesh_ipc_types::{CameraModeKind, Command, FocusMode, ZoomMode};

use crate::config::PayloadSettings;
use crate::link::Snapshot;
use crate::progress::Heights;

/// A locked screen drag turns the aircraft by `yaw_speed × DRAG_STEP_S` per message:
/// the cloud sends drags at about this period while the operator drags.
pub const DRAG_STEP_S: f64 = 0.5;
/// Gimbal pitch is clamped to this range, degrees (down negative).
pub const GIMBAL_PITCH_RANGE: (f64, f64) = (-90.0, 30.0);
/// Focus position until a manual value was set, percent.
pub const DEFAULT_MANUAL_FOCUS_PCT: f32 = 50.0;

/// What the payload methods remember between requests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PayloadMemory {
    /// The last manual focus value, percent (MF restores it).
    pub manual_focus_pct: f32,
    /// camera_look_at set an ROI that still points the camera: the next gimbal
    /// method (reset, aim, drag) clears it first (`ClearRoi`, when the cloud holds
    /// flight authority), else the ROI would keep overriding the gimbal.
    pub look_at_active: bool,
    /// camera_mode_switch 3 was acknowledged (and no 0/1 since): camera_photo_take
    /// takes a panorama. Set by the dispatcher once the mode command succeeded.
    pub panorama: bool,
}

impl Default for PayloadMemory {
    fn default() -> Self {
        PayloadMemory {
            manual_focus_pct: DEFAULT_MANUAL_FOCUS_PCT,
            look_at_active: false,
            panorama: false,
        }
    }
}

/// How to carry out one payload request.
#[derive(Debug, Clone, PartialEq)]
pub enum Plan {
    /// Send these in order; `needs_flight`: some turn the aircraft (flight authority).
    Commands {
        commands: Vec<Command>,
        needs_flight: bool,
    },
    /// camera_mode_switch: send `command`; once it succeeded the gateway's payload
    /// is in panorama mode or not ([`PayloadMemory::panorama`]).
    SwitchMode { command: Command, panorama: bool },
    /// camera_photo_take in panorama mode: a panorama from where the gimbal points
    /// (after `ClearRoi` when `clear_roi`: camera_look_at's ROI would hold the
    /// gimbal).
    Panorama { clear_roi: bool },
    /// No MAVLink equivalent on this aircraft: `PAYLOAD_UNSUPPORTED`, with why.
    Unsupported(&'static str),
    /// Refused with this code and reason.
    Reject(u32, String),
}

fn cmds(commands: Vec<Command>) -> Plan {
    Plan::Commands {
        commands,
        needs_flight: false,
    }
}

/// Pinhole camera: the yaw and pitch offsets (degrees; yaw right and pitch up
/// positive) of the image point `x`, `y` (0..=1, upper-left origin) from the centre.
pub fn aim_offsets(x: f64, y: f64, hfov_deg: f64, vfov_deg: f64) -> (f64, f64) {
    let half = |fov: f64| (fov.to_radians() / 2.0).tan();
    let yaw = ((2.0 * x - 1.0) * half(hfov_deg)).atan().to_degrees();
    let pitch = -((2.0 * y - 1.0) * half(vfov_deg)).atan().to_degrees();
    (yaw, pitch)
}

/// Degrees into (−180, 180].
pub use skymesh_runtime::angle::wrap_180_upper as wrap180;

fn clamp_pitch(p: f64) -> f32 {
    p.clamp(GIMBAL_PITCH_RANGE.0, GIMBAL_PITCH_RANGE.1) as f32
}

/// The current gimbal (pitch, yaw relative to the nose), if it reports.
pub fn gimbal(s: &Snapshot) -> Option<(f64, f64)> {
    s.payload
        .filter(|p| p.is_gimbal_valid())
        .map(|p| (f64::from(p.gimbal_pitch_deg), f64::from(p.gimbal_yaw_deg)))
        .filter(|(p, y)| p.is_finite() && y.is_finite())
}

/// `CameraZoom Range` percent for a zoom factor, or why not.
pub fn zoom_percent(zoom_factor: f64, zoom_max_factor: f64) -> Result<f32, String> {
    if !(2.0..=zoom_max_factor).contains(&zoom_factor) {
        return Err(format!(
            "zoom_factor {zoom_factor} is beyond this camera's 2..={zoom_max_factor}"
        ));
    }
    Ok((((zoom_factor - 2.0) / (zoom_max_factor - 2.0)) * 100.0).clamp(0.0, 100.0) as f32)
}

/// Maps one payload request. `heights` converts camera_look_at's height; `mem`
/// is updated by the focus and look-at methods.
pub fn plan(
    req: &ServiceRequest,
    p: &PayloadSettings,
    snap: &Snapshot,
    heights: Option<Heights>,
    mem: &mut PayloadMemory,
) -> Plan {
    use ServiceRequest as S;
    let mut plan = plan_one(req, p, snap, heights, mem);
    let moves_gimbal = matches!(
        req,
        S::GimbalReset { .. } | S::CameraAim { .. } | S::CameraScreenDrag { .. }
    );
    let clear = mem.look_at_active && snap.holds_flight();
    match (&mut plan, req) {
        (Plan::Commands { .. }, S::CameraLookAt { .. }) => mem.look_at_active = true,
        (Plan::Commands { commands, .. }, _) if moves_gimbal && clear => {
            commands.insert(0, Command::ClearRoi);
            mem.look_at_active = false;
        }
        (Plan::Panorama { clear_roi, .. }, _) if clear => {
            *clear_roi = true;
            mem.look_at_active = false;
        }
        _ => {}
    }
    plan
}

fn plan_one(
    req: &ServiceRequest,
    p: &PayloadSettings,
    snap: &Snapshot,
    heights: Option<Heights>,
    mem: &mut PayloadMemory,
) -> Plan {
    use ServiceRequest as S;
    let camera = p.camera;
    match req {
        S::CameraModeSwitch { camera_mode, .. } => {
            let (mode, panorama) = match camera_mode {
                CameraMode::Photo => (CameraModeKind::Image, false),
                CameraMode::Video => (CameraModeKind::Video, false),
                // The gimbal sweep is the gateway's; the camera takes single photos.
                CameraMode::Panorama => (CameraModeKind::Image, true),
                CameraMode::LowLight => {
                    return Plan::Unsupported("no smart low-light mode in MAVLink")
                }
            };
            Plan::SwitchMode {
                command: Command::CameraMode { camera, mode },
                panorama,
            }
        }
        // The runner checks the gimbal's attitude (it starts there) and plans the
        // stations.
        S::CameraPhotoTake { .. } if mem.panorama => Plan::Panorama { clear_roi: false },
        S::CameraPhotoTake { .. } => cmds(vec![Command::CameraCapture]),
        S::CameraPhotoStop { .. } => cmds(vec![Command::CameraCaptureStop { camera }]),
        S::CameraRecordingStart { .. } => cmds(vec![Command::RecordStart]),
        S::CameraRecordingStop { .. } => cmds(vec![Command::RecordStop]),
        S::CameraScreenDrag {
            locked,
            pitch_speed,
            yaw_speed,
            ..
        } => {
            if !*locked {
                return cmds(vec![Command::GimbalRate {
                    pitch_rate_dps: *pitch_speed as f32,
                    yaw_rate_dps: *yaw_speed as f32,
                }]);
            }
            let mut commands = vec![Command::GimbalRate {
                pitch_rate_dps: *pitch_speed as f32,
                yaw_rate_dps: 0.0,
            }];
            if *yaw_speed != 0.0 {
                commands.push(Command::SetYaw {
                    yaw_deg: (yaw_speed * DRAG_STEP_S) as f32,
                    rate_dps: yaw_speed.abs() as f32,
                    relative: true,
                });
            }
            Plan::Commands {
                needs_flight: commands.len() > 1,
                commands,
            }
        }
        S::CameraAim {
            camera_type,
            locked,
            x,
            y,
            ..
        } => {
            if *camera_type == CameraType::Ir {
                return Plan::Unsupported("this aircraft has no infrared camera");
            }
            let Some((pitch, yaw)) = gimbal(snap) else {
                return Plan::Reject(
                    codes::WRONG_STATE,
                    "the gimbal attitude is unknown: cannot aim relative to it".into(),
                );
            };
            let (d_yaw, d_pitch) = aim_offsets(*x, *y, p.hfov_deg, p.vfov_deg);
            if !*locked {
                return cmds(vec![Command::Gimbal {
                    pitch_deg: clamp_pitch(pitch + d_pitch),
                    yaw_deg: wrap180(yaw + d_yaw) as f32,
                }]);
            }
            let mut commands = vec![Command::Gimbal {
                pitch_deg: clamp_pitch(pitch + d_pitch),
                yaw_deg: wrap180(yaw) as f32,
            }];
            if d_yaw != 0.0 {
                commands.push(Command::SetYaw {
                    yaw_deg: d_yaw as f32,
                    rate_dps: 0.0,
                    relative: true,
                });
            }
            Plan::Commands {
                needs_flight: commands.len() > 1,
                commands,
            }
        }
        S::CameraFocalLengthSet {
            camera_type,
            zoom_factor,
            ..
        } => {
            if *camera_type == CameraType::Ir {
                return Plan::Unsupported("this aircraft has no infrared camera");
            }
            match zoom_percent(*zoom_factor, p.zoom_max_factor) {
                Ok(pct) => cmds(vec![Command::CameraZoom {
                    camera,
                    mode: ZoomMode::Range,
                    value: pct,
                }]),
                Err(why) => Plan::Reject(codes::OUT_OF_RANGE, why),
            }
        }
        S::GimbalReset { reset_mode, .. } => {
            let (pitch, yaw) = gimbal(snap).unwrap_or((0.0, 0.0));
            let (pitch, yaw) = match reset_mode {
                0 => (0.0, 0.0),
                1 => (-90.0, 0.0),
                2 => (pitch, 0.0),
                3 => (-90.0, yaw),
                other => {
                    return Plan::Reject(codes::NOT_IN_ENUM, format!("reset_mode {other}"));
                }
            };
            cmds(vec![Command::Gimbal {
                pitch_deg: clamp_pitch(pitch),
                yaw_deg: wrap180(yaw) as f32,
            }])
        }
        S::CameraLookAt {
            latitude,
            longitude,
            height,
            ..
        } => {
            let Some(h) = heights else {
                return Plan::Reject(
                    codes::WRONG_STATE,
                    "no home altitude yet: cannot convert the height".into(),
                );
            };
            Plan::Commands {
                commands: vec![Command::SetRoi {
                    lat_deg: *latitude,
                    lon_deg: *longitude,
                    alt_rel_m: h.rel_from_ellipsoid(*height) as f32,
                }],
                needs_flight: true,
            }
        }
        S::CameraFocusModeSet { focus_mode, .. } => {
            let (mode, value) = match focus_mode {
                0 => (FocusMode::Range, mem.manual_focus_pct),
                1 => (FocusMode::AutoSingle, 0.0),
                2 => (FocusMode::AutoContinuous, 0.0),
                other => {
                    return Plan::Reject(codes::NOT_IN_ENUM, format!("focus_mode {other}"));
                }
            };
            cmds(vec![Command::CameraFocus {
                camera,
                mode,
                value,
            }])
        }
        S::CameraFocusValueSet { focus_value, .. } => {
            if !(0..=100).contains(focus_value) {
                return Plan::Reject(
                    codes::OUT_OF_RANGE,
                    format!("focus_value {focus_value} is outside 0..=100 (percent)"),
                );
            }
            mem.manual_focus_pct = *focus_value as f32;
            cmds(vec![Command::CameraFocus {
                camera,
                mode: FocusMode::Range,
                value: mem.manual_focus_pct,
            }])
        }
        S::CameraScreenSplit { .. } => {
            Plan::Unsupported("no split-screen video on this aircraft's camera")
        }
        S::PhotoStorageSet { .. } | S::VideoStorageSet { .. } => {
            Plan::Unsupported("no MAVLink command chooses the lenses stored")
        }
        S::CameraExposureModeSet { .. } | S::CameraExposureSet { .. } => {
            Plan::Unsupported("no MAVLink camera exposure command is mapped")
        }
        S::CameraPointFocusAction { .. } => Plan::Unsupported("no MAVLink spot focus command"),
        S::IrMeteringModeSet { .. }
        | S::IrMeteringPointSet { .. }
        | S::IrMeteringAreaSet { .. } => Plan::Unsupported("this aircraft has no infrared camera"),
        other => Plan::Reject(
            codes::INTERNAL,
            format!("{} is not a payload method", other.method()),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::{PayloadState, VehicleState};

    fn settings() -> PayloadSettings {
        PayloadSettings {
            payload_index: "39-0-7".into(),
            camera: 1,
            hfov_deg: 90.0,
            vfov_deg: 60.0,
            zoom_max_factor: 10.0,
            pano_stations: 8,
            pano_pitch_deg: 0.0,
            pano_settle_timeout: std::time::Duration::from_secs(10),
        }
    }

    fn snap_with_gimbal(pitch: f32, yaw: f32) -> Snapshot {
        Snapshot {
            payload: Some(PayloadState {
                gimbal_valid: 1,
                gimbal_pitch_deg: pitch,
                gimbal_yaw_deg: yaw,
                ..Default::default()
            }),
            state: Some(VehicleState::default()),
            ..Default::default()
        }
    }

    fn run(req: ServiceRequest, snap: &Snapshot) -> Plan {
        plan(&req, &settings(), snap, None, &mut PayloadMemory::default())
    }

    fn pi() -> String {
        "39-0-7".into()
    }

    #[test]
    fn camera_modes_and_captures() {
        let s = Snapshot::default();
        let switch = |camera_mode| ServiceRequest::CameraModeSwitch {
            payload_index: pi(),
            camera_mode,
        };
        for (mode, kind, panorama) in [
            (CameraMode::Photo, CameraModeKind::Image, false),
            (CameraMode::Video, CameraModeKind::Video, false),
            (CameraMode::Panorama, CameraModeKind::Image, true),
        ] {
            assert_eq!(
                run(switch(mode), &s),
                Plan::SwitchMode {
                    command: Command::CameraMode {
                        camera: 1,
                        mode: kind
                    },
                    panorama
                },
                "{mode:?}"
            );
        }
        assert!(matches!(
            run(switch(CameraMode::LowLight), &s),
            Plan::Unsupported(_)
        ));
        assert_eq!(
            run(
                ServiceRequest::CameraPhotoStop {
                    payload_index: pi()
                },
                &s
            ),
            cmds(vec![Command::CameraCaptureStop { camera: 1 }])
        );
        assert_eq!(
            run(
                ServiceRequest::CameraRecordingStart {
                    payload_index: pi()
                },
                &s
            ),
            cmds(vec![Command::RecordStart])
        );
    }

    #[test]
    fn photo_take_in_panorama_mode_plans_a_panorama() {
        use skymesh_ipc_types::{AuthorityState, CommandSource};
        let take = ServiceRequest::CameraPhotoTake {
            payload_index: pi(),
        };
        let mut s = snap_with_gimbal(-30.0, 20.0);
        let mut mem = PayloadMemory::default();
        assert_eq!(
            plan(&take, &settings(), &s, None, &mut mem),
            cmds(vec![Command::CameraCapture]),
            "not in panorama mode"
        );
        mem.panorama = true;
        assert_eq!(
            plan(&take, &settings(), &s, None, &mut mem),
            Plan::Panorama { clear_roi: false }
        );
        // An ROI from camera_look_at would hold the gimbal: cleared first.
        s.authority = Some(AuthorityState {
            flight_holder: CommandSource::DjiDrc.to_wire(),
            ..Default::default()
        });
        mem.look_at_active = true;
        assert_eq!(
            plan(&take, &settings(), &s, None, &mut mem),
            Plan::Panorama { clear_roi: true }
        );
        assert!(!mem.look_at_active);
    }

    #[test]
    fn aim_geometry_is_a_pinhole() {
        // Centre: no offset. Right edge of a 90° lens: 45° right. Top of a 60° lens: 30° up.
        let (y, p) = aim_offsets(0.5, 0.5, 90.0, 60.0);
        assert!(y.abs() < 1e-9 && p.abs() < 1e-9);
        let (y, _) = aim_offsets(1.0, 0.5, 90.0, 60.0);
        assert!((y - 45.0).abs() < 1e-9);
        let (_, p) = aim_offsets(0.5, 0.0, 90.0, 60.0);
        assert!((p - 30.0).abs() < 1e-9);
        // A quarter of the way right: atan(0.5·tan 45°) = 26.565°, not 22.5° (linear).
        let (y, _) = aim_offsets(0.75, 0.5, 90.0, 60.0);
        assert!((y - 26.565).abs() < 1e-3, "{y}");
        let (_, p) = aim_offsets(0.5, 1.0, 90.0, 60.0);
        assert!((p + 30.0).abs() < 1e-9, "bottom = down");
    }

    #[test]
    fn camera_aim_adds_the_offset_to_the_current_gimbal() {
        let s = snap_with_gimbal(-20.0, 170.0);
        let aim = |locked, x, y| ServiceRequest::CameraAim {
            payload_index: pi(),
            camera_type: CameraType::Zoom,
            locked,
            x,
            y,
        };
        match run(aim(false, 1.0, 0.0), &s) {
            Plan::Commands {
                commands,
                needs_flight: false,
            } => match commands[..] {
                [Command::Gimbal { pitch_deg, yaw_deg }] => {
                    assert!((pitch_deg - 10.0).abs() < 1e-4, "{pitch_deg}");
                    assert!((yaw_deg + 145.0).abs() < 1e-4, "wrapped: {yaw_deg}");
                }
                ref other => panic!("{other:?}"),
            },
            other => panic!("{other:?}"),
        }
        // Locked: the aircraft yaws by the offset; the gimbal keeps its yaw.
        match run(aim(true, 0.0, 1.0), &s) {
            Plan::Commands {
                commands,
                needs_flight: true,
            } => {
                assert!(matches!(commands[0], Command::Gimbal { pitch_deg, yaw_deg }
                    if (pitch_deg + 50.0).abs() < 1e-4 && (yaw_deg - 170.0).abs() < 1e-4));
                assert!(
                    matches!(commands[1], Command::SetYaw { yaw_deg, relative: true, .. }
                    if (yaw_deg + 45.0).abs() < 1e-4)
                );
            }
            other => panic!("{other:?}"),
        }
        // Pitch is clamped at straight down.
        let down = snap_with_gimbal(-80.0, 0.0);
        assert!(matches!(run(aim(false, 0.5, 1.0), &down),
            Plan::Commands { commands, .. } if commands == vec![Command::Gimbal { pitch_deg: -90.0, yaw_deg: 0.0 }]));
        assert!(matches!(
            run(aim(false, 0.5, 0.5), &Snapshot::default()),
            Plan::Reject(codes::WRONG_STATE, _)
        ));
        let ir = ServiceRequest::CameraAim {
            payload_index: pi(),
            camera_type: CameraType::Ir,
            locked: false,
            x: 0.5,
            y: 0.5,
        };
        assert!(matches!(run(ir, &s), Plan::Unsupported(_)));
    }

    #[test]
    fn screen_drag_turns_the_gimbal_or_the_aircraft() {
        let s = Snapshot::default();
        let drag = |locked, yaw| ServiceRequest::CameraScreenDrag {
            payload_index: pi(),
            locked,
            pitch_speed: -10.0,
            yaw_speed: yaw,
        };
        assert_eq!(
            run(drag(false, 20.0), &s),
            cmds(vec![Command::GimbalRate {
                pitch_rate_dps: -10.0,
                yaw_rate_dps: 20.0
            }])
        );
        assert_eq!(
            run(drag(true, -20.0), &s),
            Plan::Commands {
                commands: vec![
                    Command::GimbalRate {
                        pitch_rate_dps: -10.0,
                        yaw_rate_dps: 0.0
                    },
                    Command::SetYaw {
                        yaw_deg: -10.0,
                        rate_dps: 20.0,
                        relative: true
                    }
                ],
                needs_flight: true
            }
        );
        assert!(matches!(
            run(drag(true, 0.0), &s),
            Plan::Commands {
                needs_flight: false,
                ..
            }
        ));
    }

    #[test]
    fn zoom_factor_maps_to_range_percent() {
        assert_eq!(zoom_percent(2.0, 10.0), Ok(0.0));
        assert_eq!(zoom_percent(6.0, 10.0), Ok(50.0));
        assert_eq!(zoom_percent(10.0, 10.0), Ok(100.0));
        assert!(zoom_percent(10.5, 10.0).is_err());
        let s = Snapshot::default();
        let zoom = |camera_type, zoom_factor| ServiceRequest::CameraFocalLengthSet {
            payload_index: pi(),
            camera_type,
            zoom_factor,
        };
        assert_eq!(
            run(zoom(CameraType::Zoom, 4.0), &s),
            cmds(vec![Command::CameraZoom {
                camera: 1,
                mode: ZoomMode::Range,
                value: 25.0
            }])
        );
        assert!(matches!(
            run(zoom(CameraType::Wide, 11.0), &s),
            Plan::Reject(codes::OUT_OF_RANGE, _)
        ));
        assert!(matches!(
            run(zoom(CameraType::Ir, 4.0), &s),
            Plan::Unsupported(_)
        ));
    }

    #[test]
    fn gimbal_reset_modes() {
        let s = snap_with_gimbal(-30.0, 40.0);
        let expect = [
            (0, 0.0, 0.0),
            (1, -90.0, 0.0),
            (2, -30.0, 0.0),
            (3, -90.0, 40.0),
        ];
        for (mode, pitch, yaw) in expect {
            assert_eq!(
                run(
                    ServiceRequest::GimbalReset {
                        payload_index: pi(),
                        reset_mode: mode
                    },
                    &s
                ),
                cmds(vec![Command::Gimbal {
                    pitch_deg: pitch,
                    yaw_deg: yaw
                }]),
                "mode {mode}"
            );
        }
    }

    #[test]
    fn look_at_converts_the_height_and_needs_flight() {
        let h = Heights {
            home_msl_m: 500.0,
            undulation_m: 10.0,
        };
        let req = ServiceRequest::CameraLookAt {
            payload_index: pi(),
            locked: false,
            latitude: 1.0,
            longitude: 2.0,
            height: 560.0,
        };
        let mut mem = PayloadMemory::default();
        assert_eq!(
            plan(&req, &settings(), &Snapshot::default(), Some(h), &mut mem),
            Plan::Commands {
                commands: vec![Command::SetRoi {
                    lat_deg: 1.0,
                    lon_deg: 2.0,
                    alt_rel_m: 50.0
                }],
                needs_flight: true
            }
        );
        assert!(matches!(
            plan(&req, &settings(), &Snapshot::default(), None, &mut mem),
            Plan::Reject(codes::WRONG_STATE, _)
        ));
    }

    #[test]
    fn a_gimbal_method_after_look_at_clears_the_roi_first() {
        use skymesh_ipc_types::{AuthorityState, CommandSource};
        let h = Heights {
            home_msl_m: 500.0,
            undulation_m: 0.0,
        };
        let mut s = snap_with_gimbal(-30.0, 0.0);
        s.authority = Some(AuthorityState {
            flight_holder: CommandSource::DjiDrc.to_wire(),
            ..Default::default()
        });
        let look = ServiceRequest::CameraLookAt {
            payload_index: pi(),
            locked: false,
            latitude: 1.0,
            longitude: 2.0,
            height: 510.0,
        };
        let reset = ServiceRequest::GimbalReset {
            payload_index: pi(),
            reset_mode: 0,
        };
        let mut mem = PayloadMemory::default();
        let centre = Command::Gimbal {
            pitch_deg: 0.0,
            yaw_deg: 0.0,
        };
        assert_eq!(
            plan(&reset, &settings(), &s, Some(h), &mut mem),
            cmds(vec![centre])
        );
        plan(&look, &settings(), &s, Some(h), &mut mem);
        assert!(mem.look_at_active);
        assert_eq!(
            plan(&reset, &settings(), &s, Some(h), &mut mem),
            cmds(vec![Command::ClearRoi, centre])
        );
        assert_eq!(
            plan(&reset, &settings(), &s, Some(h), &mut mem),
            cmds(vec![centre]),
            "cleared once"
        );
    }

    #[test]
    fn manual_focus_remembers_the_last_value() {
        let s = Snapshot::default();
        let p = settings();
        let mut mem = PayloadMemory::default();
        let mode = |focus_mode| ServiceRequest::CameraFocusModeSet {
            payload_index: pi(),
            camera_type: CameraType::Zoom,
            focus_mode,
        };
        let value = |focus_value| ServiceRequest::CameraFocusValueSet {
            payload_index: pi(),
            camera_type: CameraType::Zoom,
            focus_value,
        };
        let focus = |mode, value| {
            cmds(vec![Command::CameraFocus {
                camera: 1,
                mode,
                value,
            }])
        };
        assert_eq!(
            plan(&mode(0), &p, &s, None, &mut mem),
            focus(FocusMode::Range, 50.0)
        );
        assert_eq!(
            plan(&mode(1), &p, &s, None, &mut mem),
            focus(FocusMode::AutoSingle, 0.0)
        );
        assert_eq!(
            plan(&mode(2), &p, &s, None, &mut mem),
            focus(FocusMode::AutoContinuous, 0.0)
        );
        assert_eq!(
            plan(&value(70), &p, &s, None, &mut mem),
            focus(FocusMode::Range, 70.0)
        );
        assert_eq!(
            plan(&mode(0), &p, &s, None, &mut mem),
            focus(FocusMode::Range, 70.0)
        );
        assert!(matches!(
            plan(&value(101), &p, &s, None, &mut mem),
            Plan::Reject(codes::OUT_OF_RANGE, _)
        ));
        assert_eq!(
            mem.manual_focus_pct, 70.0,
            "a refused value is not remembered"
        );
    }

    #[test]
    fn methods_without_a_mavlink_equivalent_are_unsupported() {
        let s = Snapshot::default();
        for req in [
            ServiceRequest::CameraScreenSplit {
                payload_index: pi(),
                enable: true,
            },
            ServiceRequest::CameraExposureModeSet {
                payload_index: pi(),
                camera_type: CameraType::Zoom,
                exposure_mode: 1,
            },
            ServiceRequest::CameraPointFocusAction {
                payload_index: pi(),
                camera_type: CameraType::Zoom,
                x: 0.5,
                y: 0.5,
            },
            ServiceRequest::IrMeteringModeSet {
                payload_index: pi(),
                mode: 1,
            },
        ] {
            assert!(matches!(run(req, &s), Plan::Unsupported(_)));
        }
    }
}
