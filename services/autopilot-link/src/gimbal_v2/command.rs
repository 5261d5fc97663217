//! COMMAND_LONG / COMMAND_INT to a virtual gimbal: pitch/yaw, configure, ROI,
//! zoom, request message; answered at once or after the pipeline replies.

use super::*;

impl GimbalV2 {
    #[allow(clippy::too_many_arguments)]
    pub(super) fn command(
        &mut self,
        from: (u8, u8),
        target_component: u8,
        command: MavCmd,
        p: [f32; 7],
        int: Option<(MavFrame, i32, i32)>,
        home_alt_msl: Option<f32>,
        now_ns: u64,
        out: &mut Output,
    ) {
        let Some(cam) = self.cam_of(target_component) else {
            // Broadcast commands are the autopilot's to answer.
            return;
        };
        let component = target_component;
        let (msg, decision) = match command {
            MavCmd::MAV_CMD_REQUEST_MESSAGE => {
                let id = p[0];
                let sent = match id as u32 {
                    _ if !id.is_finite() || id.fract() != 0.0 || id < 0.0 => None,
                    MSG_GIMBAL_MANAGER_INFORMATION => Some(self.information(cam, now_ns)),
                    MSG_GIMBAL_MANAGER_STATUS => self.status(cam, now_ns),
                    MSG_GIMBAL_DEVICE_ATTITUDE_STATUS => self.attitude(cam, now_ns),
                    _ => None,
                };
                let result = match sent {
                    Some(m) => {
                        out.sends.push((component, m));
                        MavResult::MAV_RESULT_ACCEPTED
                    }
                    None if [MSG_GIMBAL_MANAGER_STATUS, MSG_GIMBAL_DEVICE_ATTITUDE_STATUS]
                        .contains(&(id as u32)) =>
                    {
                        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
                    }
                    None => MavResult::MAV_RESULT_UNSUPPORTED,
                };
                (
                    "request_message",
                    Decision::Answer(result, "message not provided"),
                )
            }
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE => {
                let d = if !self.device_ok(p[6], component) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "wrong gimbal device id")
                } else {
                    match self.slots[cam]
                        .control
                        .configure([p[0], p[1], p[2], p[3]], from)
                    {
                        Ok(()) => Decision::Answer(MavResult::MAV_RESULT_ACCEPTED, ""),
                        Err(_) => Decision::Answer(
                            MavResult::MAV_RESULT_DENIED,
                            "control ids must be integers -3..=255",
                        ),
                    }
                };
                ("configure", d)
            }
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW => {
                let d = if !self.device_ok(p[6], component) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "wrong gimbal device id")
                } else if !self.slots[cam].control.allows(from) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "not in control")
                } else if !p[4].is_finite() || p[4] < 0.0 || p[4] > u32::MAX as f32 {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "bad flags")
                } else {
                    let r = |d: f32| d.to_radians();
                    self.attitude_control(cam, p[4] as u32, [r(p[1]), r(p[0]), r(p[3]), r(p[2])])
                };
                ("pitchyaw", d)
            }
            MavCmd::MAV_CMD_DO_SET_ROI_LOCATION => {
                let d = if !self.device_ok(p[0], component) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "wrong gimbal device id")
                } else if !self.slots[cam].control.allows(from) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "not in control")
                } else {
                    self.roi(cam, p, int, home_alt_msl)
                };
                ("roi_location", d)
            }
            MavCmd::MAV_CMD_DO_SET_ROI_NONE => {
                let d = if !self.device_ok(p[0], component) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "wrong gimbal device id")
                } else if !self.slots[cam].control.allows(from) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "not in control")
                } else {
                    Decision::Ask(self.control_for(VisionControlKind::RoiNone, cam))
                };
                ("roi_none", d)
            }
            MavCmd::MAV_CMD_SET_CAMERA_ZOOM => {
                let camera_ok = p[2].is_nan()
                    || p[2] == 0.0
                    || p[2] == f32::from(component)
                    || (1.0..=6.0).contains(&p[2]) && p[2].fract() == 0.0;
                let d = match zoom(p[0], p[1]) {
                    _ if !camera_ok => {
                        Decision::Answer(MavResult::MAV_RESULT_DENIED, "another camera's id")
                    }
                    Some((mode, value)) => {
                        let mut c = self.control_for(VisionControlKind::Zoom, cam);
                        c.zoom_mode = mode;
                        c.value = value;
                        Decision::Ask(c)
                    }
                    None => {
                        Decision::Answer(MavResult::MAV_RESULT_DENIED, "bad zoom type or value")
                    }
                };
                ("zoom", d)
            }
            _ => (
                "unsupported_command",
                Decision::Answer(MavResult::MAV_RESULT_UNSUPPORTED, "not implemented"),
            ),
        };
        match decision {
            Decision::Ask(c) => {
                self.remember(
                    c.request_id,
                    Waiting::Command {
                        to: from,
                        component,
                        command,
                        msg,
                    },
                    now_ns,
                );
                out.controls.push(c);
            }
            Decision::Answer(result, why) => {
                if result != MavResult::MAV_RESULT_ACCEPTED {
                    out.warnings
                        .push(("refused", format!("{msg} from {from:?}: {why}")));
                }
                out.sends.push((component, ack(command, result, from)));
                out.counts.push((msg, outcome_of(result)));
            }
        }
    }

    fn device_ok(&self, p: f32, component: u8) -> bool {
        p.is_nan() || p == 0.0 || p == f32::from(component)
    }

    fn roi(
        &mut self,
        cam: usize,
        p: [f32; 7],
        int: Option<(MavFrame, i32, i32)>,
        home_alt_msl: Option<f32>,
    ) -> Decision {
        let (lat, lon, relative) = match int {
            Some((frame, x, y)) => {
                let relative = match frame {
                    MavFrame::MAV_FRAME_GLOBAL => false,
                    MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT => true,
                    // The superseded *_INT synonyms (5, 6), still sent by many.
                    #[allow(deprecated)]
                    MavFrame::MAV_FRAME_GLOBAL_INT => false,
                    #[allow(deprecated)]
                    MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT => true,
                    _ => {
                        return Decision::Answer(
                            MavResult::MAV_RESULT_UNSUPPORTED,
                            "only global MSL or relative-altitude frames",
                        )
                    }
                };
                (f64::from(x) * 1e-7, f64::from(y) * 1e-7, relative)
            }
            None => (f64::from(p[4]), f64::from(p[5]), true),
        };
        let alt = p[6];
        if !lat.is_finite()
            || !lon.is_finite()
            || lat.abs() > 90.0
            || lon.abs() > 180.0
            || !alt.is_finite()
            || !(-1000.0..=20_000.0).contains(&alt)
        {
            return Decision::Answer(MavResult::MAV_RESULT_DENIED, "location out of range");
        }
        let alt_msl = if relative {
            match home_alt_msl {
                Some(h) => h + alt,
                None => {
                    return Decision::Answer(
                        MavResult::MAV_RESULT_TEMPORARILY_REJECTED,
                        "home is not known yet (relative altitude)",
                    )
                }
            }
        } else {
            alt
        };
        let mut c = self.control_for(VisionControlKind::RoiLocation, cam);
        c.lat_deg = lat;
        c.lon_deg = lon;
        c.alt_msl_m = alt_msl;
        Decision::Ask(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gimbal_v2::test_support::*;

    #[test]
    fn configure_sets_leaves_and_releases_control() {
        let mut c = Control::default();
        assert!(c.allows(GCS) && c.allows(OTHER));
        c.configure([-2.0, -2.0, -1.0, -1.0], GCS).unwrap();
        assert_eq!(c.primary, GCS);
        assert!(c.allows(GCS) && !c.allows(OTHER));
        // -1 leaves, explicit ids set the secondary.
        c.configure([-1.0, -1.0, 254.0, 190.0], OTHER).unwrap();
        assert_eq!((c.primary, c.secondary), (GCS, OTHER));
        assert!(c.allows(OTHER));
        // -3 releases only what the sender holds.
        c.configure([-3.0, -3.0, -1.0, -1.0], OTHER).unwrap();
        assert_eq!(c.primary, GCS);
        c.configure([-3.0, -3.0, -3.0, -3.0], GCS).unwrap();
        assert_eq!(c.primary, (0, 0));
        assert_eq!(c.secondary, OTHER);
        // 0 = nobody.
        c.configure([-1.0, -1.0, 0.0, 0.0], GCS).unwrap();
        assert_eq!(c, Control::default());
        // Bad values change nothing.
        for bad in [f32::NAN, -4.0, 256.0, 1.5, f32::INFINITY] {
            assert!(c.configure([bad, -1.0, -1.0, -1.0], GCS).is_err());
            assert_eq!(c, Control::default());
        }
    }

    #[test]
    fn bad_values_are_denied_without_asking_the_pipeline() {
        let mut g = gimbals();
        let bad = [
            long(
                154,
                MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
                [f32::INFINITY, 0.0, f32::NAN, f32::NAN, 0.0, 0.0, 0.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
                [-95.0, 0.0, f32::NAN, f32::NAN, 0.0, 0.0, 0.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
                [0.0, 0.0, f32::NAN, f32::NAN, 0.0, 0.0, 171.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
                [2.0, 150.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
                [9.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
                [2.0, 50.0, 100.0, 0.0, 0.0, 0.0, 0.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
                [0.0, 0.0, 0.0, 0.0, 95.0, 8.0, 10.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
                [0.0, 0.0, 0.0, 0.0, 47.0, f32::NAN, 10.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE,
                [1.5, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0],
            ),
        ];
        for cmd in bad {
            let out = handle(&mut g, GCS, cmd.clone(), Some(400.0));
            assert!(out.controls.is_empty(), "{cmd:?}");
            assert_eq!(acks(&out).len(), 1, "{cmd:?}");
            assert_eq!(acks(&out)[0].2, MavResult::MAV_RESULT_DENIED, "{cmd:?}");
        }
        // Retract and unknown commands are unsupported.
        let retract = long(
            154,
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
            [0.0, 0.0, f32::NAN, f32::NAN, 1.0, 0.0, 0.0],
        );
        assert_eq!(
            acks(&handle(&mut g, GCS, retract, None))[0].2,
            MavResult::MAV_RESULT_UNSUPPORTED
        );
        let other = long(154, MavCmd::MAV_CMD_DO_SET_SERVO, [0.0; 7]);
        let out = handle(&mut g, GCS, other, None);
        assert_eq!(acks(&out)[0].2, MavResult::MAV_RESULT_UNSUPPORTED);
        assert_eq!(out.counts, vec![("unsupported_command", "unsupported")]);
        // Commands to other components (the autopilot's) are not ours to answer.
        let out = handle(
            &mut g,
            GCS,
            long(1, MavCmd::MAV_CMD_DO_SET_ROI_NONE, [0.0; 7]),
            None,
        );
        assert!(out.sends.is_empty() && out.controls.is_empty());
    }

    #[test]
    fn roi_altitudes_follow_the_frame() {
        let mut g = gimbals();
        let msl = handle(
            &mut g,
            GCS,
            roi_int(MavFrame::MAV_FRAME_GLOBAL, 500.0),
            None,
        );
        let c = msl.controls[0];
        assert_eq!(c.kind, VisionControlKind::RoiLocation.to_wire());
        assert!((c.lat_deg - 47.397742).abs() < 1e-9 && (c.lon_deg - 8.545594).abs() < 1e-9);
        assert_eq!(c.alt_msl_m, 500.0);
        let rel = handle(
            &mut g,
            GCS,
            roi_int(MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT, 20.0),
            Some(400.0),
        );
        assert_eq!(rel.controls[0].alt_msl_m, 420.0);
        let no_home = handle(
            &mut g,
            GCS,
            roi_int(MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT, 20.0),
            None,
        );
        assert!(no_home.controls.is_empty());
        assert_eq!(
            acks(&no_home)[0].2,
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED
        );
        let terrain = handle(
            &mut g,
            GCS,
            roi_int(MavFrame::MAV_FRAME_GLOBAL_TERRAIN_ALT, 20.0),
            Some(400.0),
        );
        assert_eq!(acks(&terrain)[0].2, MavResult::MAV_RESULT_UNSUPPORTED);
        // COMMAND_LONG: degrees in params 5/6, altitude above home.
        let cmd = long(
            154,
            MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
            [0.0, 0.0, 0.0, 0.0, 47.5, 8.5, 30.0],
        );
        let c = handle(&mut g, GCS, cmd, Some(400.0)).controls[0];
        assert_eq!(
            (c.lat_deg as f32, c.lon_deg as f32, c.alt_msl_m),
            (47.5, 8.5, 430.0)
        );
    }

    #[test]
    fn zoom_command_carries_type_and_value() {
        let mut g = gimbals();
        let cmd = long(
            173,
            MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
            [1.0, -1.0, 173.0, 0.0, 0.0, 0.0, 0.0],
        );
        let c = handle(&mut g, GCS, cmd, None).controls[0];
        assert_eq!(c.kind, VisionControlKind::Zoom.to_wire());
        assert_eq!((c.cam, c.zoom_mode, c.value), (3, 1, -1.0));
    }
}
