//! What the virtual gimbals send unasked: HEARTBEAT, GIMBAL_MANAGER_INFORMATION and
//! STATUS, GIMBAL_DEVICE_ATTITUDE_STATUS in telemetry slots; reply timeouts; the
//! COMMAND_ACK encoding.

use super::*;

impl GimbalV2 {
    /// When [`poll`](Self::poll) has something to do next. With no camera shown and
    /// none still marked announced, a telemetry slot would send nothing: no slot is
    /// due until a new [`on_state`](Self::on_state) shows a camera (the service
    /// waits for every `VisionState` and asks again after it), so a mesh without a
    /// vision pipeline does not wake 10 times a second for nothing.
    pub fn next_deadline_ns(&self, now_ns: u64) -> u64 {
        let slot = if self.slots_idle(now_ns) {
            u64::MAX
        } else {
            self.next_slot_ns
        };
        self.pending
            .values()
            .map(|p| p.deadline_ns)
            .fold(slot, u64::min)
    }

    /// True when a telemetry slot at `now_ns` would do nothing.
    fn slots_idle(&self, now_ns: u64) -> bool {
        self.slots.iter().all(|s| !s.announced) && self.active(now_ns).is_empty()
    }

    fn time_boot_ms(&self, now_ns: u64) -> u32 {
        (now_ns.saturating_sub(self.boot_ns) / 1_000_000) as u32
    }

    /// Telemetry and reply timeouts.
    pub fn poll(&mut self, now_ns: u64, out: &mut Output) {
        let expired: Vec<u64> = self
            .pending
            .iter()
            .filter(|(_, p)| p.deadline_ns <= now_ns)
            .map(|(id, _)| *id)
            .collect();
        for id in expired {
            if let Some(p) = self.pending.remove(&id) {
                self.finish(p.waiting, MavResult::MAV_RESULT_FAILED, out);
                out.warnings.push((
                    "no_reply",
                    "the vision pipeline did not answer within 1 s".to_string(),
                ));
            }
        }
        if now_ns < self.next_slot_ns {
            return;
        }
        let k = self.slot_index;
        self.slot_index += 1;
        self.next_slot_ns = if self.next_slot_ns + SLOT_NS <= now_ns {
            now_ns + SLOT_NS
        } else {
            self.next_slot_ns + SLOT_NS
        };
        let active = self.active(now_ns);
        // Cameras that left the layout announce themselves again when they return.
        for (i, slot) in self.slots.iter_mut().enumerate() {
            if !active.iter().any(|(a, _)| *a == i) {
                slot.announced = false;
            }
        }
        for (i, component) in active {
            if k.is_multiple_of(10) {
                out.sends.push((component, heartbeat()));
            }
            if !self.slots[i].announced {
                self.slots[i].announced = true;
                out.sends.push((component, self.information(i, now_ns)));
            }
            if k.is_multiple_of(2) {
                if let Some(m) = self.status(i, now_ns) {
                    out.sends.push((component, m));
                }
            }
            if let Some(m) = self.attitude(i, now_ns) {
                out.sends.push((component, m));
            }
        }
    }

    /// GIMBAL_MANAGER_INFORMATION of camera `i`.
    pub fn information(&self, i: usize, now_ns: u64) -> MavMessage {
        let pi = std::f32::consts::PI;
        let half = std::f32::consts::FRAC_PI_2;
        MavMessage::GIMBAL_MANAGER_INFORMATION(GIMBAL_MANAGER_INFORMATION_DATA {
            time_boot_ms: self.time_boot_ms(now_ns),
            cap_flags: GimbalManagerCapFlags::from_bits_truncate(CAP_FLAGS),
            roll_min: 0.0,
            roll_max: 0.0,
            pitch_min: -half,
            pitch_max: half,
            yaw_min: -pi,
            yaw_max: pi,
            gimbal_device_id: self.slots[i].component,
        })
    }

    /// GIMBAL_MANAGER_STATUS of camera `i` (needs a fresh state).
    pub fn status(&self, i: usize, now_ns: u64) -> Option<MavMessage> {
        let cam = self.fresh_view(now_ns)?.cams[i];
        let c = self.slots[i].control;
        Some(MavMessage::GIMBAL_MANAGER_STATUS(
            GIMBAL_MANAGER_STATUS_DATA {
                time_boot_ms: self.time_boot_ms(now_ns),
                flags: GimbalManagerFlags::from_bits_truncate(lock_flags(&cam)),
                gimbal_device_id: self.slots[i].component,
                primary_control_sysid: c.primary.0,
                primary_control_compid: c.primary.1,
                secondary_control_sysid: c.secondary.0,
                secondary_control_compid: c.secondary.1,
            },
        ))
    }

    /// GIMBAL_DEVICE_ATTITUDE_STATUS of camera `i`: earth frame (see the module doc).
    pub fn attitude(&self, i: usize, now_ns: u64) -> Option<MavMessage> {
        let cam = self.fresh_view(now_ns)?.cams[i];
        let flags = (lock_flags(&cam) & (FLAG_ROLL_LOCK | FLAG_PITCH_LOCK | FLAG_YAW_LOCK))
            | FLAG_YAW_IN_EARTH_FRAME;
        Some(MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(
            GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
                target_system: 0,
                target_component: 0,
                time_boot_ms: self.time_boot_ms(now_ns),
                flags: GimbalDeviceFlags::from_bits_truncate(flags as u16),
                q: cam.ned_from_cam_q,
                angular_velocity_x: f32::NAN,
                angular_velocity_y: f32::NAN,
                angular_velocity_z: f32::NAN,
                failure_flags: GimbalDeviceErrorFlags::empty(),
                // The view's attitude is in the earth frame; we do not relate it
                // to the vehicle's heading here.
                delta_yaw: f32::NAN,
                delta_yaw_velocity: f32::NAN,
                // The device is the sending component itself.
                gimbal_device_id: 0,
            },
        ))
    }
}

/// Our HEARTBEAT as a gimbal.
pub fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_GIMBAL,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// COMMAND_ACK for `command` addressed to `to` (system, component), the sender of
/// the command, as ArduPilot addresses its acks.
pub fn ack(command: MavCmd, result: MavResult, to: (u8, u8)) -> MavMessage {
    MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
        command,
        result,
        target_system: to.0,
        target_component: to.1,
        ..COMMAND_ACK_DATA::DEFAULT
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gimbal_v2::test_support::*;

    #[test]
    fn no_slot_is_due_while_no_camera_is_shown() {
        let mut g = gimbals();
        // Nothing shown, nothing announced: no telemetry slot to wait for.
        assert_eq!(g.next_deadline_ns(T0), u64::MAX);
        // A camera shown: slots run, and the first announces it.
        g.on_state(&state(&[1], T0));
        let due = g.next_deadline_ns(T0);
        assert!(due <= T0 + SLOT_NS);
        let mut out = Output::default();
        g.poll(due.max(T0), &mut out);
        assert!(!out.sends.is_empty());
        // The state goes stale: one more slot un-announces the camera (so it
        // announces itself again when it returns), then nothing is due.
        let stale = T0 + STATE_FRESH_NS;
        let due = g.next_deadline_ns(stale);
        assert_ne!(due, u64::MAX);
        let mut out = Output::default();
        g.poll(stale.max(due), &mut out);
        assert!(out.sends.is_empty());
        assert_eq!(g.next_deadline_ns(stale + SLOT_NS), u64::MAX);
    }

    #[test]
    fn telemetry_only_for_active_cameras_of_a_fresh_state() {
        let mut g = gimbals();
        let mut out = Output::default();
        g.poll(T0, &mut out);
        assert!(out.sends.is_empty(), "no state, no telemetry");
        g.on_state(&state(&[0, 1], T0));
        let mut out = Output::default();
        g.poll(T0 + SLOT_NS, &mut out);
        let from = |out: &Output, c: u8, name: &str| {
            out.sends
                .iter()
                .filter(|(comp, m)| *comp == c && m.message_name() == name)
                .count()
        };
        for c in [154, 171] {
            assert_eq!(from(&out, c, "GIMBAL_MANAGER_INFORMATION"), 1);
            assert_eq!(from(&out, c, "GIMBAL_DEVICE_ATTITUDE_STATUS"), 1);
        }
        assert!(out.sends.iter().all(|(c, _)| [154, 171].contains(c)));
        // Over one second: 1 heartbeat, 5 status, 10 attitude per camera; info once.
        let mut out = Output::default();
        for k in 2..12 {
            g.poll(T0 + k * SLOT_NS, &mut out);
        }
        assert_eq!(from(&out, 154, "HEARTBEAT"), 1);
        assert_eq!(from(&out, 154, "GIMBAL_MANAGER_STATUS"), 5);
        assert_eq!(from(&out, 171, "GIMBAL_DEVICE_ATTITUDE_STATUS"), 10);
        assert_eq!(from(&out, 154, "GIMBAL_MANAGER_INFORMATION"), 0);
        let Some(MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(a)) = g.attitude(0, T0) else {
            panic!("attitude");
        };
        assert_eq!(a.q, [0.9, 0.1, -0.3, 0.3]);
        let f = u32::from(a.flags.bits());
        assert_eq!(f, FLAG_YAW_IN_EARTH_FRAME | FLAG_YAW_LOCK | FLAG_PITCH_LOCK);
        let Some(MavMessage::HEARTBEAT(h)) = out
            .sends
            .iter()
            .map(|(_, m)| m)
            .find(|m| m.message_name() == "HEARTBEAT")
            .cloned()
        else {
            panic!("heartbeat");
        };
        assert_eq!(h.mavtype, MavType::MAV_TYPE_GIMBAL);
        assert_eq!(h.autopilot, MavAutopilot::MAV_AUTOPILOT_INVALID);
        // Stale (2 s after its stamp): silent.
        let mut out = Output::default();
        g.poll(T0 + STATE_FRESH_NS, &mut out);
        assert!(out.sends.is_empty());
    }

    #[test]
    fn information_is_sent_on_request() {
        let mut g = gimbals();
        let req = long(
            171,
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [280.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        let out = handle(&mut g, GCS, req, None);
        let Some((171, MavMessage::GIMBAL_MANAGER_INFORMATION(i))) = out.sends.first().cloned()
        else {
            panic!("{:?}", out.sends);
        };
        assert_eq!(i.gimbal_device_id, 171);
        assert_eq!(i.cap_flags.bits(), CAP_FLAGS);
        assert!((i.pitch_min + std::f32::consts::FRAC_PI_2).abs() < 1e-6);
        assert!((i.yaw_max - std::f32::consts::PI).abs() < 1e-6);
        assert_eq!(acks(&out)[0].2, MavResult::MAV_RESULT_ACCEPTED);
        let req = long(
            171,
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [259.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(
            acks(&handle(&mut g, GCS, req, None))[0].2,
            MavResult::MAV_RESULT_UNSUPPORTED
        );
    }
}
