//! Requests to the vision pipeline and their answers: a pending request per
//! `VisionControl`, finished by the pipeline's `VisionReply` or its timeout.

use super::*;

impl GimbalV2 {
    pub(super) fn control_for(&mut self, kind: VisionControlKind, cam: usize) -> VisionControl {
        let id = self.next_request;
        self.next_request = self.next_request.wrapping_add(1).max(1);
        VisionControl {
            request_id: id,
            kind: kind.to_wire(),
            origin: VisionOrigin::GimbalV2.to_wire(),
            stream: self.stream as u8,
            cam: cam as u8,
            ..VisionControl::default()
        }
    }

    pub(super) fn remember(&mut self, id: u64, waiting: Waiting, now_ns: u64) {
        if self.pending.len() >= MAX_PENDING {
            // The oldest entry is answered FAILED by poll anyway; make room.
            if let Some(oldest) = self
                .pending
                .iter()
                .min_by_key(|(_, p)| p.deadline_ns)
                .map(|(k, _)| *k)
            {
                self.pending.remove(&oldest);
            }
        }
        self.pending.insert(
            id,
            Pending {
                waiting,
                deadline_ns: now_ns + REPLY_TIMEOUT_NS,
            },
        );
    }

    pub(super) fn finish(&self, waiting: Waiting, result: MavResult, out: &mut Output) {
        match waiting {
            Waiting::Command {
                to,
                component,
                command,
                msg,
            } => {
                out.sends.push((component, ack(command, result, to)));
                out.counts.push((msg, outcome_of(result)));
            }
            Waiting::Counted { msg } => out.counts.push((msg, outcome_of(result))),
        }
    }

    /// The pipeline's answer to one of our requests (others' replies are ignored).
    pub fn on_reply(&mut self, reply: &VisionReply, out: &mut Output) {
        if let Some(p) = self.pending.remove(&reply.request_id) {
            let result = reply.result();
            if result != VisionResult::Applied {
                out.warnings.push((
                    "refused",
                    format!(
                        "the vision pipeline answered {}: {}",
                        result.as_str(),
                        reply.message.as_str()
                    ),
                ));
            }
            self.finish(p.waiting, ack_of(result), out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gimbal_v2::test_support::*;

    #[test]
    fn pitchyaw_command_is_acked_by_the_pipeline_answer() {
        let cases = [
            (VisionResult::Applied, MavResult::MAV_RESULT_ACCEPTED),
            (VisionResult::Ignored, MavResult::MAV_RESULT_DENIED),
            (VisionResult::Unsupported, MavResult::MAV_RESULT_UNSUPPORTED),
            (VisionResult::Invalid, MavResult::MAV_RESULT_FAILED),
            (VisionResult::Failed, MavResult::MAV_RESULT_FAILED),
        ];
        for (result, expected) in cases {
            let mut g = gimbals();
            let cmd = long(
                172,
                MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
                [-30.0, 45.0, f32::NAN, f32::NAN, 0.0, 0.0, 0.0],
            );
            let out = handle(&mut g, GCS, cmd, None);
            assert!(acks(&out).is_empty(), "no ack before the pipeline answers");
            let c = out.controls[0];
            assert_eq!(c.cam, 2);
            assert!((c.pitch_rad + 30f32.to_radians()).abs() < 1e-6);
            assert!((c.yaw_rad - 45f32.to_radians()).abs() < 1e-6);
            let mut out = Output::default();
            // Someone else's reply changes nothing.
            g.on_reply(&reply(c.request_id + 99, result), &mut out);
            assert!(out.sends.is_empty());
            g.on_reply(&reply(c.request_id, result), &mut out);
            assert_eq!(
                acks(&out),
                vec![(172, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, expected)]
            );
            // Answered once only.
            let mut again = Output::default();
            g.on_reply(&reply(c.request_id, result), &mut again);
            assert!(again.sends.is_empty());
        }
    }

    #[test]
    fn no_reply_within_a_second_is_failed() {
        let mut g = gimbals();
        let cmd = long(154, MavCmd::MAV_CMD_DO_SET_ROI_NONE, [0.0; 7]);
        let out = handle(&mut g, GCS, cmd, None);
        assert_eq!(out.controls[0].kind, VisionControlKind::RoiNone.to_wire());
        let mut out = Output::default();
        g.poll(T0 + REPLY_TIMEOUT_NS - 1, &mut out);
        assert!(acks(&out).is_empty());
        g.poll(T0 + REPLY_TIMEOUT_NS, &mut out);
        assert_eq!(
            acks(&out),
            vec![(
                154,
                MavCmd::MAV_CMD_DO_SET_ROI_NONE,
                MavResult::MAV_RESULT_FAILED
            )]
        );
    }
}
