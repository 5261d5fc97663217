//! Camera commands other gateways sent (accepted by the arbiter), forwarded to the
//! virtual cameras.

use super::*;

impl GimbalV2 {
    /// An accepted camera/gimbal `VehicleCommand` for the virtual cameras (origin
    /// `Payload`); `None` for commands that do not concern them.
    pub fn forward_payload(
        &mut self,
        command: &Command,
        now_ns: u64,
        out: &mut Output,
    ) -> Option<()> {
        let all = 255usize;
        let c = match *command {
            Command::CameraZoom {
                camera,
                mode,
                value,
            } => {
                let cam = if camera == 0 {
                    all
                } else {
                    usize::from(camera - 1)
                };
                let mut c = self.control_for(VisionControlKind::Zoom, cam);
                c.zoom_mode = mode.to_wire();
                c.value = value;
                c
            }
            Command::Gimbal { pitch_deg, yaw_deg } => {
                // Autopilot-link sends these with YAW_IN_VEHICLE_FRAME; camera 0.
                let mut c = self.control_for(VisionControlKind::GimbalAttitude, 0);
                c.gimbal_flags = FLAG_YAW_IN_VEHICLE_FRAME;
                c.pitch_rad = pitch_deg.to_radians();
                c.yaw_rad = yaw_deg.to_radians();
                c
            }
            Command::GimbalRate {
                pitch_rate_dps,
                yaw_rate_dps,
            } => {
                let mut c = self.control_for(VisionControlKind::GimbalAttitude, 0);
                c.gimbal_flags = FLAG_YAW_IN_VEHICLE_FRAME;
                c.pitch_rate_rps = pitch_rate_dps.to_radians();
                c.yaw_rate_rps = yaw_rate_dps.to_radians();
                c
            }
            Command::CameraCapture => self.control_for(VisionControlKind::ImageCapture, all),
            Command::RecordStart => self.control_for(VisionControlKind::RecordStart, all),
            Command::RecordStop => self.control_for(VisionControlKind::RecordStop, all),
            _ => return None,
        };
        let c = VisionControl {
            origin: VisionOrigin::Payload.to_wire(),
            ..c
        };
        self.remember(c.request_id, Waiting::Counted { msg: "payload" }, now_ns);
        out.controls.push(c);
        Some(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gimbal_v2::test_support::*;

    #[test]
    fn payload_commands_map_cameras_and_origin() {
        let mut g = gimbals();
        let mut out = Output::default();
        let zoom = |camera| Command::CameraZoom {
            camera,
            mode: ZoomMode::Range,
            value: 40.0,
        };
        g.forward_payload(&zoom(0), T0, &mut out).unwrap();
        g.forward_payload(&zoom(2), T0, &mut out).unwrap();
        g.forward_payload(
            &Command::Gimbal {
                pitch_deg: -90.0,
                yaw_deg: 10.0,
            },
            T0,
            &mut out,
        )
        .unwrap();
        g.forward_payload(&Command::RecordStart, T0, &mut out)
            .unwrap();
        assert!(g
            .forward_payload(
                &Command::Servo {
                    channel: 9,
                    pwm_us: 1500
                },
                T0,
                &mut out
            )
            .is_none());
        let cams: Vec<u8> = out.controls.iter().map(|c| c.cam).collect();
        assert_eq!(cams, [255, 1, 0, 255]);
        assert!(out
            .controls
            .iter()
            .all(|c| c.origin == VisionOrigin::Payload.to_wire()));
        assert_eq!(
            (out.controls[0].zoom_mode, out.controls[0].value),
            (2, 40.0)
        );
        let g1 = out.controls[2];
        assert_eq!(g1.gimbal_flags, FLAG_YAW_IN_VEHICLE_FRAME);
        assert!((g1.pitch_rad + std::f32::consts::FRAC_PI_2).abs() < 1e-6);
        assert_eq!(
            out.controls[3].kind,
            VisionControlKind::RecordStart.to_wire()
        );
        // Request ids are unique.
        let mut ids: Vec<u64> = out.controls.iter().map(|c| c.request_id).collect();
        ids.dedup();
        assert_eq!(ids.len(), 4);
    }
}
