//! Frames addressed to the virtual gimbals: which cameras they are for, and the
//! gimbal manager attitude messages (SET_ATTITUDE, SET_PITCHYAW).

use super::*;

impl GimbalV2 {
    /// The cameras a message/command addressed to `target_component` with device id
    /// `device` means (empty: not for us).
    fn cams_for(&self, target_component: u8, device: u8) -> Vec<usize> {
        match self.cam_of(target_component) {
            Some(i) if device == 0 || device == target_component => vec![i],
            Some(_) => Vec::new(),
            None if target_component == 0 => match device {
                0 => (0..self.slots.len()).collect(),
                d => self.cam_of(d).into_iter().collect(),
            },
            None => Vec::new(),
        }
    }

    /// A decoded frame delivered to the virtual cameras. `home_alt_msl` is the
    /// autopilot's home altitude, if known.
    pub fn handle(
        &mut self,
        incoming: Incoming<'_>,
        home_alt_msl: Option<f32>,
        now_ns: u64,
        out: &mut Output,
    ) {
        let from = incoming.from;
        match incoming.msg {
            MavMessage::GIMBAL_MANAGER_SET_ATTITUDE(m) => {
                if !self.for_our_system(m.target_system) {
                    return;
                }
                let flags = m.flags.bits();
                let (yaw, pitch) = yaw_pitch_of(m.q).unwrap_or((f32::NAN, f32::NAN));
                let q_set = !m.q.iter().any(|v| v.is_nan());
                if q_set && yaw.is_nan() {
                    out.counts.push(("set_attitude", "invalid"));
                    return;
                }
                for cam in self.cams_for(m.target_component, m.gimbal_device_id) {
                    self.attitude_message(
                        "set_attitude",
                        cam,
                        from,
                        flags,
                        [yaw, pitch, m.angular_velocity_z, m.angular_velocity_y],
                        now_ns,
                        out,
                    );
                }
            }
            MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(m) => {
                if !self.for_our_system(m.target_system) {
                    return;
                }
                for cam in self.cams_for(m.target_component, m.gimbal_device_id) {
                    self.attitude_message(
                        "set_pitchyaw",
                        cam,
                        from,
                        m.flags.bits(),
                        [m.yaw, m.pitch, m.yaw_rate, m.pitch_rate],
                        now_ns,
                        out,
                    );
                }
            }
            MavMessage::COMMAND_LONG(c) => {
                let p = [
                    c.param1, c.param2, c.param3, c.param4, c.param5, c.param6, c.param7,
                ];
                self.command(
                    from,
                    c.target_component,
                    c.command,
                    p,
                    None,
                    home_alt_msl,
                    now_ns,
                    out,
                );
            }
            MavMessage::COMMAND_INT(c) => {
                let p = [
                    c.param1, c.param2, c.param3, c.param4, c.x as f32, c.y as f32, c.z,
                ];
                self.command(
                    from,
                    c.target_component,
                    c.command,
                    p,
                    Some((c.frame, c.x, c.y)),
                    home_alt_msl,
                    now_ns,
                    out,
                );
            }
            _ => {}
        }
    }

    fn for_our_system(&self, target_system: u8) -> bool {
        target_system == 0 || target_system == self.system
    }

    /// SET_ATTITUDE / SET_PITCHYAW: `v` = yaw, pitch, yaw rate, pitch rate (rad, rad/s).
    #[allow(clippy::too_many_arguments)]
    fn attitude_message(
        &mut self,
        msg: &'static str,
        cam: usize,
        from: (u8, u8),
        flags: u32,
        v: [f32; 4],
        now_ns: u64,
        out: &mut Output,
    ) {
        if !self.slots[cam].control.allows(from) {
            out.counts.push((msg, "not_in_control"));
            out.warnings.push((
                "not_in_control",
                format!("{msg} from {from:?} dropped: another controller is configured"),
            ));
            return;
        }
        match self.attitude_control(cam, flags, v) {
            Decision::Ask(c) => {
                self.remember(c.request_id, Waiting::Counted { msg }, now_ns);
                out.controls.push(c);
            }
            Decision::Answer(r, why) => {
                out.counts.push((msg, outcome_of(r)));
                out.warnings
                    .push(("invalid", format!("{msg} dropped: {why}")));
            }
        }
    }

    /// A GimbalAttitude for camera `cam`, or why not.
    pub(super) fn attitude_control(&mut self, cam: usize, flags: u32, v: [f32; 4]) -> Decision {
        if flags & FLAG_RETRACT != 0 {
            return Decision::Answer(
                MavResult::MAV_RESULT_UNSUPPORTED,
                "retract is not supported",
            );
        }
        let [mut yaw, mut pitch, yaw_rate, pitch_rate] = v;
        let mut flags = flags;
        if flags & FLAG_NEUTRAL != 0 {
            (yaw, pitch) = (0.0, 0.0);
            flags &= !(FLAG_YAW_LOCK | FLAG_YAW_IN_EARTH_FRAME);
        }
        if !angles_ok(yaw, pitch, yaw_rate, pitch_rate) {
            return Decision::Answer(
                MavResult::MAV_RESULT_DENIED,
                "angle or rate not finite, out of range, or nothing set",
            );
        }
        let mut c = self.control_for(VisionControlKind::GimbalAttitude, cam);
        c.gimbal_flags = flags;
        c.yaw_rad = yaw;
        c.pitch_rad = pitch;
        c.yaw_rate_rps = yaw_rate;
        c.pitch_rate_rps = pitch_rate;
        Decision::Ask(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gimbal_v2::test_support::*;

    #[test]
    fn set_pitchyaw_becomes_a_gimbal_attitude_for_its_camera() {
        let mut g = gimbals();
        let out = handle(&mut g, GCS, pitchyaw_msg(171, 0, -0.5, 1.0), None);
        assert_eq!(out.controls.len(), 1);
        let c = out.controls[0];
        assert_eq!(c.kind, VisionControlKind::GimbalAttitude.to_wire());
        assert_eq!(c.origin, VisionOrigin::GimbalV2.to_wire());
        assert_eq!((c.stream, c.cam), (0, 1));
        assert_eq!((c.yaw_rad, c.pitch_rad), (1.0, -0.5));
        assert!(c.yaw_rate_rps.is_nan() && c.pitch_rate_rps.is_nan());
        assert_eq!(c.gimbal_flags, FLAG_YAW_LOCK);
        assert!(acks(&out).is_empty(), "messages are not acked");
        // The reply is counted.
        let mut out = Output::default();
        g.on_reply(&reply(c.request_id, VisionResult::Applied), &mut out);
        assert_eq!(out.counts, vec![("set_pitchyaw", "accepted")]);
        // Out of range or NaN everywhere: dropped, nothing asked.
        for (p, y) in [
            (2.0, 0.0),
            (0.0, 4.0),
            (f32::NAN, f32::NAN),
            (f32::INFINITY, 0.0),
        ] {
            let out = handle(&mut g, GCS, pitchyaw_msg(171, 0, p, y), None);
            assert!(out.controls.is_empty(), "{p} {y}");
            assert_eq!(out.counts, vec![("set_pitchyaw", "denied")]);
        }
    }

    #[test]
    fn broadcast_messages_pick_cameras_by_device_id() {
        let mut g = gimbals();
        let all = handle(&mut g, GCS, pitchyaw_msg(0, 0, 0.1, 0.2), None);
        assert_eq!(
            all.controls.iter().map(|c| c.cam).collect::<Vec<_>>(),
            [0, 1, 2, 3]
        );
        let one = handle(&mut g, GCS, pitchyaw_msg(0, 172, 0.1, 0.2), None);
        assert_eq!(one.controls.iter().map(|c| c.cam).collect::<Vec<_>>(), [2]);
        // A real gimbal's device id, another component, a wrong device: not ours.
        assert!(handle(&mut g, GCS, pitchyaw_msg(0, 100, 0.1, 0.2), None)
            .controls
            .is_empty());
        assert!(handle(&mut g, GCS, pitchyaw_msg(1, 0, 0.1, 0.2), None)
            .controls
            .is_empty());
        assert!(handle(&mut g, GCS, pitchyaw_msg(154, 171, 0.1, 0.2), None)
            .controls
            .is_empty());
    }

    #[test]
    fn set_attitude_takes_yaw_and_pitch_from_the_quaternion_and_rates() {
        let mut g = gimbals();
        let (yaw, pitch) = (0.5f32, -0.3f32);
        let q = UnitQuaternion::from_euler_angles(0.2, pitch, yaw);
        let msg = |q: [f32; 4], rates: [f32; 3]| {
            MavMessage::GIMBAL_MANAGER_SET_ATTITUDE(GIMBAL_MANAGER_SET_ATTITUDE_DATA {
                target_system: SYS,
                target_component: 154,
                flags: GimbalManagerFlags::from_bits_truncate(FLAG_YAW_IN_EARTH_FRAME),
                gimbal_device_id: 0,
                q,
                angular_velocity_x: rates[0],
                angular_velocity_y: rates[1],
                angular_velocity_z: rates[2],
            })
        };
        let qa = [q.w, q.i, q.j, q.k];
        let out = handle(&mut g, GCS, msg(qa, [f32::NAN; 3]), None);
        let c = out.controls[0];
        assert!((c.yaw_rad - yaw).abs() < 1e-5 && (c.pitch_rad - pitch).abs() < 1e-5);
        assert_eq!(c.gimbal_flags, FLAG_YAW_IN_EARTH_FRAME);
        // NaN quaternion + rates: rates only (x = roll rate ignored).
        let out = handle(&mut g, GCS, msg([f32::NAN; 4], [9.0, 0.1, -0.2]), None);
        let c = out.controls[0];
        assert!(c.yaw_rad.is_nan() && c.pitch_rad.is_nan());
        assert_eq!((c.yaw_rate_rps, c.pitch_rate_rps), (-0.2, 0.1));
        // A zero quaternion is invalid; a rate beyond 360°/s too.
        let out = handle(&mut g, GCS, msg([0.0; 4], [f32::NAN; 3]), None);
        assert!(out.controls.is_empty());
        assert_eq!(out.counts, vec![("set_attitude", "invalid")]);
        let out = handle(&mut g, GCS, msg([f32::NAN; 4], [0.0, 0.0, 7.0]), None);
        assert!(out.controls.is_empty());
    }

    #[test]
    fn a_primary_controller_excludes_everybody_else() {
        let mut g = gimbals();
        let cfg = long(
            154,
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE,
            [-2.0, -2.0, -1.0, -1.0, 0.0, 0.0, 0.0],
        );
        let out = handle(&mut g, GCS, cfg, None);
        assert_eq!(acks(&out)[0].2, MavResult::MAV_RESULT_ACCEPTED);
        assert_eq!(g.control(0).unwrap().primary, GCS);
        // Reflected in the status.
        g.on_state(&state(&[0], T0));
        let Some(MavMessage::GIMBAL_MANAGER_STATUS(s)) = g.status(0, T0) else {
            panic!("status");
        };
        assert_eq!((s.primary_control_sysid, s.primary_control_compid), GCS);
        // Another ground station: commands denied, messages dropped and counted.
        let cmd = long(
            154,
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
            [0.0, 0.0, f32::NAN, f32::NAN, 0.0, 0.0, 0.0],
        );
        let out = handle(&mut g, OTHER, cmd.clone(), None);
        assert!(out.controls.is_empty());
        assert_eq!(acks(&out)[0].2, MavResult::MAV_RESULT_DENIED);
        let roi = long(154, MavCmd::MAV_CMD_DO_SET_ROI_NONE, [0.0; 7]);
        assert_eq!(
            acks(&handle(&mut g, OTHER, roi, None))[0].2,
            MavResult::MAV_RESULT_DENIED
        );
        let out = handle(&mut g, OTHER, pitchyaw_msg(154, 0, 0.0, 0.0), None);
        assert!(out.controls.is_empty());
        assert_eq!(out.counts, vec![("set_pitchyaw", "not_in_control")]);
        // Zoom is not gimbal control; the controller itself goes through; camera 1 is free.
        let zoom = long(
            154,
            MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
            [2.0, 50.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(handle(&mut g, OTHER, zoom, None).controls.len(), 1);
        assert_eq!(handle(&mut g, GCS, cmd, None).controls.len(), 1);
        assert_eq!(
            handle(&mut g, OTHER, pitchyaw_msg(171, 0, 0.0, 0.0), None)
                .controls
                .len(),
            1
        );
    }
}
