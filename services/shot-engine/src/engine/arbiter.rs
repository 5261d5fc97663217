//! The arbiter's answers: who holds authority, what it did on its own, and the ack
//! of every command we sent (refusals are counted; some end the flying shot, see
//! [`super::flight`]; GoPro acks update the GoPro model; the app's home request is
//! answered in [`super::rewind`]).

use skymesh_ipc_types::{
    ArbiterEvent, ArbiterEventKind, AuthorityChange, AuthorityDomain, AuthorityState, CommandAck,
    CommandKind, CommandSource, RefusalReason,
};

use super::{shot_title, Engine, ExitReason};

impl Engine {
    pub fn handle_authority(&mut self, st: &AuthorityState, _now_ns: u64) {
        if st.vehicle_id != self.settings.vehicle_id {
            return;
        }
        let Some(flight) = self.active.as_mut().and_then(|a| a.flight.as_mut()) else {
            return;
        };
        if st.emergency != 0 {
            tracing::warn!("emergency stop in force; ending the shot");
            self.exit_shot(ExitReason::Emergency);
            return;
        }
        match st.flight() {
            Some(CommandSource::ShotEngine) => flight.confirmed = true,
            holder if flight.confirmed => {
                let reason = if holder.is_some() {
                    ExitReason::Preempted
                } else if AuthorityChange::try_from(st.flight_change)
                    == Ok(AuthorityChange::LinkLost)
                {
                    ExitReason::LinkDown
                } else {
                    ExitReason::AuthorityLost
                };
                tracing::warn!(
                    holder = holder.map_or("nobody", CommandSource::as_str),
                    "flight authority lost; ending the shot"
                );
                self.exit_shot(reason);
            }
            _ => {}
        }
    }

    pub fn handle_arbiter_event(&mut self, ev: &ArbiterEvent, _now_ns: u64) {
        if ev.vehicle_id != self.settings.vehicle_id {
            return;
        }
        let ours = ev.source == CommandSource::ShotEngine.to_wire();
        let flying = self.is_flying();
        let detail = ev.detail.as_str();
        match ev.event_kind() {
            Some(ArbiterEventKind::EmergencyStop) if self.active.is_some() => {
                tracing::warn!(detail, "emergency stop; ending the shot");
                self.exit_shot(ExitReason::Emergency);
            }
            Some(ArbiterEventKind::LinkLost) if self.active.is_some() => {
                tracing::warn!(detail, "autopilot link lost; ending the shot");
                self.exit_shot(ExitReason::LinkDown);
            }
            Some(
                kind @ (ArbiterEventKind::GeofenceUpdated | ArbiterEventKind::GeofenceInvalid),
            ) if ours && ev.request_id != 0 => {
                self.geofence_decided(
                    ev.request_id,
                    kind == ArbiterEventKind::GeofenceUpdated,
                    detail,
                );
            }
            Some(ArbiterEventKind::StaleBrake) if ours && flying => {
                tracing::warn!(detail, "the arbiter braked: our setpoints arrived late");
            }
            // "flight: shot_engine -> operator (preempted)": the loser is named as source.
            Some(ArbiterEventKind::AuthorityChanged)
                if ours && flying && detail.starts_with("flight:") =>
            {
                let reason = if detail.ends_with("(preempted)") {
                    Some(ExitReason::Preempted)
                } else if detail.ends_with("(emergency)") {
                    Some(ExitReason::Emergency)
                } else if detail.ends_with("(timeout)") {
                    Some(ExitReason::AuthorityLost)
                } else {
                    None
                };
                if let Some(reason) = reason {
                    tracing::warn!(detail, "flight authority lost; ending the shot");
                    self.exit_shot(reason);
                }
            }
            _ => {}
        }
    }

    pub fn handle_ack(&mut self, ack: &CommandAck, now_ns: u64) {
        if ack.vehicle_id != self.settings.vehicle_id
            || ack.source != CommandSource::ShotEngine.to_wire()
        {
            return;
        }
        let accepted = ack.is_accepted();
        let reason = ack.reason().unwrap_or(RefusalReason::None);
        let kind = CommandKind::try_from(ack.kind).ok();
        if !accepted {
            self.out.metrics.command_refused(reason.as_str());
            let kind_name = kind.map_or("unknown", |k| k.as_str());
            if kind.is_some_and(|k| k.is_setpoint()) {
                tracing::debug!(command_id = ack.command_id, %reason, detail = ack.detail.as_str(), "setpoint refused");
            } else {
                tracing::warn!(command_id = ack.command_id, kind = kind_name, %reason, detail = ack.detail.as_str(), "command refused");
            }
        }
        if self.gopro_ack(ack, accepted) || self.home_ack(ack, accepted, now_ns) {
            return;
        }
        self.geofence_ack(ack, accepted);
        if accepted {
            return;
        }
        let Some(flight) = self.active.as_ref().and_then(|a| a.flight.as_ref()) else {
            return;
        };
        if ack.command_id < flight.first_command_id
            || kind.and_then(|k| k.authority()) != Some(AuthorityDomain::Flight)
        {
            return;
        }
        let exit = match reason {
            RefusalReason::NoAuthority if flight.confirmed => Some(ExitReason::Preempted),
            RefusalReason::NoAuthority => Some(ExitReason::NoAuthority),
            RefusalReason::Preempted => Some(ExitReason::Preempted),
            RefusalReason::Emergency => Some(ExitReason::Emergency),
            RefusalReason::LinkDown => Some(ExitReason::LinkDown),
            _ if Some(ack.command_id) == flight.guided_command_id => {
                Some(ExitReason::GuidedRefused)
            }
            _ => None,
        };
        if let Some(exit) = exit {
            let shot = self.active.as_ref().map_or(-1, |a| a.shot);
            if exit == ExitReason::GuidedRefused || exit == ExitReason::NoAuthority {
                self.out.error(&format!(
                    "{}: the vehicle refused ({reason}: {}); shot ended",
                    shot_title(shot),
                    ack.detail.as_str()
                ));
            }
            self.exit_shot(exit);
        }
    }
}
