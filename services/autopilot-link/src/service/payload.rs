//! The event loop's side of the payload: gimbal and GoPro telemetry into
//! `PayloadState` samples, GOPRO_SET_RESPONSE into the answer of a `GoProSet`.

use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::MavHeader;
use skymesh_runtime::clock::monotonic_ns;

use super::Service;
use crate::Lifecycle;

impl<L: Lifecycle> Service<L> {
    /// Gimbal attitude, GoPro heartbeat and GoPro answers.
    pub(super) fn on_payload_message(
        &mut self,
        header: &MavHeader,
        msg: &MavMessage,
        now: Instant,
    ) -> anyhow::Result<()> {
        let vehicle_yaw = self.last_state.as_ref().map(|s| s.yaw_rad.to_degrees());
        let u = self
            .payload
            .handle(header, msg, vehicle_yaw, monotonic_ns());
        if let Some(e) = u.attitude_error {
            tracing::debug!(error = %e, component = header.component_id, "gimbal attitude not used");
        }
        if let Some(r) = u.gopro_response {
            let answer = self.tracker.on_gopro_response(r.cmd_id, r.success, now);
            self.metrics.gopro_response(answer.is_some(), r.success);
            match answer {
                Some(a) => self.answer(a)?,
                None => tracing::debug!(
                    cmd_id = r.cmd_id,
                    success = r.success,
                    "GOPRO_SET_RESPONSE nobody here waits for"
                ),
            }
        }
        self.publish_payload_if_due()
    }

    /// Publishes `PayloadState` when it changed, once a second, and when a source went quiet.
    pub(super) fn publish_payload_if_due(&mut self) -> anyhow::Result<()> {
        if let Some(state) = self.payload.due(monotonic_ns()) {
            self.ports.payload.publish(state)?;
        }
        Ok(())
    }

    pub(super) fn payload_deadline(&self) -> Instant {
        let due = self.payload.next_deadline_ns();
        Instant::now() + Duration::from_nanos(due.saturating_sub(monotonic_ns()))
    }
}
