//! The command arbiter: every `VehicleCommand` that passed intake is decided here
//! before anything reaches MAVLink (../shared/DESIGN.md §3). Pure: no I/O, every
//! time is `CLOCK_MONOTONIC` ns passed in, so it is tested without sleeping.
//!
//! [`Arbiter::decide`] checks, in order, and the first failure refuses:
//!
//! | step | refusal |
//! |---|---|
//! | the sample decodes to a valid command (again: nothing bypasses the range checks) | `InvalidParameter` |
//! | no emergency stop in force, unless the sender is the safety source or the command is `EmergencyStop`, `ReleaseEmergency` or `ClearEmergency` (decided here, see below) | `Emergency` |
//! | the autopilot flies its failsafe (RTL, LAND, SmartRTL): a source below manual RC may not change the mode or the motion ([`failsafe_refusal`]; `FailsafeHeld` event) | `AutopilotFailsafe` |
//! | a forced arm (skips the pre-arm checks) comes from safety or operator | `Denied` |
//! | authority ([`authority`]: implicit grab, pre-emption by priority) | `NoAuthority` |
//! | a setpoint is fresh ([`freshness`]) | `Stale` |
//! | in the air ([`in_air`]): a motor kill is flagged as an emergency kill, no forced disarm, no motor test, a servo only on a channel of `servo_channels_in_flight` | `InAir` |
//! | `SetHome`: the current home is known (`WrongState`), the new one within `max_home_move_m` of it and `max_home_alt_change_m` of its altitude (`Denied`), inside every fence (`Geofence`) | as said |
//! | speed limits from the config (reduce → `Limited`) and the geofence ([`geofence`]: position targets refused, velocities reduced → `Limited`) | `Geofence` |
//!
//! Only a command that passes every step changes authority (so a refused command
//! from a higher-priority source pre-empts nobody) and feeds the setpoint stream.
//!
//! An emergency stop always passes, from any source, and is owned by its engagers
//! ([`authority`]): safety takes flight authority and keeps it while any engager's
//! stop is in force. `ReleaseEmergency` withdraws the sender's own stop
//! (`EmergencyReleased`; the last one ends the stop: `EmergencyCleared`, flight
//! authority released); `ClearEmergency` ends it whoever engaged it, only from
//! operator or safety (`Denied` otherwise; the event names the sender and the
//! engagers). Releasing authority never ends a stop. The stops and the fences
//! survive a restart ([`persist`]).
//!
//! [`Arbiter::poll`] does what is due without a command: quiet holders lose
//! authority, and a stopped setpoint stream is braked. A source flying to a position
//! target (`GoTo`, `Takeoff`) that loses flight authority by timeout or pre-emption
//! is braked too ([`Effect::TargetBrake`]); the target ends with any other motion
//! command (velocity, brake, land, RTL, mode change, emergency stop).
//!
//! In the air means armed and (position unknown or more than `in_air_alt_m` above
//! home or moving faster than `in_air_speed_mps`): conservative, an armed vehicle of
//! unknown position is in the air. A vehicle armed on a hill above home counts as
//! flying; `Disarm` (the autopilot's own landed check) remains for that case.

pub mod audit;
pub mod authority;
mod decision;
mod emergency;
mod envelope;
mod failsafe;
pub mod fence_stack;
#[cfg(test)]
mod fence_stack_tests;
mod fence_stopping;
#[cfg(test)]
mod fence_stopping_tests;
pub mod freshness;
pub mod geofence;
#[cfg(test)]
mod geofence_tests;
mod home;
pub mod in_air;
#[cfg(test)]
mod in_air_tests;
pub mod persist;
#[cfg(test)]
mod safety_tests;
mod target;
#[cfg(test)]
mod tests;
mod vehicle;

use std::time::Duration;

use skymesh_ipc_types::{
    ArbiterEventKind, AuthorityChange, AuthorityDomain, Command, CommandKind, CommandSource,
    RefusalReason, VehicleCommand,
};

use authority::{Authority, Change, Claim};
use decision::refused;
pub use decision::{Decision, Effect, Outcome};
use failsafe::{failsafe_refusal, in_failsafe};
use fence_stack::FenceStack;
use freshness::{Freshness, FreshnessPolicy, Streams};
use geofence::Envelope;
pub use home::Home;
use target::Target;
pub use vehicle::{Kinematics, VehicleView};

/// The arbiter's configuration (validated in [`crate::config`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ArbiterSettings {
    /// A holder not heard from for this long loses its authority.
    pub authority_timeout: Duration,
    /// Maximum age of a setpoint that names none and whose source has no default.
    pub setpoint_max_age: Duration,
    /// The most a setpoint may ask for in `max_age_ms`.
    pub setpoint_max_age_cap: Duration,
    /// Per-source default maximum ages.
    pub setpoint_max_age_by_source: Vec<(CommandSource, Duration)>,
    pub max_horizontal_speed_mps: f32,
    pub max_climb_mps: f32,
    pub max_descent_mps: f32,
    pub max_yaw_rate_dps: f32,
    pub fence_deceleration_mps2: f32,
    pub fence_margin_m: f32,
    pub fence_vertical_margin_m: f32,
    pub fence_response_s: f32,
    pub in_air_alt_m: f32,
    pub in_air_speed_mps: f32,
    /// Servo channels a `Servo` command may drive while in the air (sorted, each
    /// 1..=32); every other channel is refused `InAir` in flight ([`in_air`]).
    pub servo_channels_in_flight: Vec<u8>,
    /// `SetHome` may move home at most this far (m, horizontally).
    pub max_home_move_m: f32,
    /// ... and change its altitude (AMSL) by at most this much (m).
    pub max_home_alt_change_m: f32,
}

fn domain_name(d: AuthorityDomain) -> &'static str {
    match d {
        AuthorityDomain::Flight => "flight",
        AuthorityDomain::Payload => "payload",
    }
}

/// Flight commands that replace whatever a velocity stream was doing (`SetHome`
/// moves nothing, so a stream goes on and is still braked if it stops).
fn ends_stream(kind: CommandKind) -> bool {
    kind.authority() == Some(AuthorityDomain::Flight)
        && !matches!(
            kind,
            CommandKind::VelocityNed
                | CommandKind::SetYaw
                | CommandKind::SetRoi
                | CommandKind::ClearRoi
                | CommandKind::SetHome
        )
}

const NS_PER_MS: u64 = 1_000_000;

/// The arbiter of one vehicle. `Clone`: the service decides a retransmission
/// again on a copy, which changes nothing here.
#[derive(Debug, Clone)]
pub struct Arbiter {
    settings: ArbiterSettings,
    authority: Authority,
    policy: FreshnessPolicy,
    streams: Streams,
    envelope: Envelope,
    /// One fence per source, all enforced ([`fence_stack`]).
    fence: FenceStack,
    /// The last velocity setpoint was reduced by the fence (events on the edges only).
    fence_limiting: bool,
    link_up: bool,
    /// Who flies to a position target (`GoTo`, `Takeoff`) now, and where: braked
    /// when it loses flight authority by timeout or pre-emption before arriving.
    position_target: Option<Target>,
    /// Sources told (`FailsafeHeld`) during the current autopilot failsafe, as a
    /// bitmask (one event per source and failsafe, not one per refused setpoint).
    failsafe_told: u8,
    scratch: Vec<f64>,
}

impl Arbiter {
    pub fn new(settings: ArbiterSettings) -> Self {
        let ns = |d: Duration| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        let mut by_source = [None; CommandSource::ALL.len()];
        for (source, age) in &settings.setpoint_max_age_by_source {
            by_source[usize::from(source.to_wire())] = Some(ns(*age));
        }
        Arbiter {
            authority: Authority::new(ns(settings.authority_timeout)),
            policy: FreshnessPolicy {
                default_ns: ns(settings.setpoint_max_age),
                cap_ns: ns(settings.setpoint_max_age_cap),
                by_source,
            },
            streams: Streams::default(),
            envelope: Envelope {
                decel_mps2: settings.fence_deceleration_mps2.into(),
                margin_m: settings.fence_margin_m.into(),
                vertical_margin_m: settings.fence_vertical_margin_m.into(),
                response_s: settings.fence_response_s.into(),
            },
            settings,
            fence: FenceStack::default(),
            fence_limiting: false,
            link_up: false,
            position_target: None,
            failsafe_told: 0,
            scratch: Vec::with_capacity(32),
        }
    }

    pub fn authority(&self) -> &Authority {
        &self.authority
    }

    /// Decides one command sample at `now_ns`.
    pub fn decide(
        &mut self,
        now_ns: u64,
        sample: &VehicleCommand,
        vehicle: &VehicleView,
    ) -> Decision {
        let mut effects = Vec::new();
        let outcome = self.outcome(now_ns, sample, vehicle, &mut effects);
        Decision { outcome, effects }
    }

    fn outcome(
        &mut self,
        now_ns: u64,
        sample: &VehicleCommand,
        vehicle: &VehicleView,
        effects: &mut Vec<Effect>,
    ) -> Outcome {
        let decoded = sample.source().and_then(|s| Ok((s, sample.command()?)));
        let (source, command) = match decoded {
            Ok(x) => x,
            Err(e) => return refused(e.reason(), e.to_string()),
        };
        let kind = command.kind();
        if self.authority.in_emergency()
            && source != CommandSource::Safety
            && !matches!(
                kind,
                CommandKind::EmergencyStop
                    | CommandKind::ReleaseEmergency
                    | CommandKind::ClearEmergency
            )
        {
            return refused(
                RefusalReason::Emergency,
                "emergency stop: only safety may command",
            );
        }
        match kind {
            CommandKind::EmergencyStop => {
                effects.extend(
                    self.authority
                        .emergency(source, sample.command_id, now_ns)
                        .map(Effect::Authority),
                );
                self.streams.end();
                self.position_target = None;
                effects.push(Effect::Event {
                    kind: ArbiterEventKind::EmergencyStop,
                    source: Some(source),
                    detail: format!("emergency stop by {source}: braking, safety holds"),
                });
                return Outcome::Execute {
                    command,
                    limited: None,
                };
            }
            CommandKind::ReleaseEmergency => {
                return self.release_emergency(now_ns, source, effects)
            }
            CommandKind::ClearEmergency => return self.clear_emergency(now_ns, source, effects),
            _ => {}
        }
        if let Some(detail) = failsafe_refusal(vehicle.mode, source, &command) {
            let bit = 1 << source.to_wire();
            if self.failsafe_told & bit == 0 {
                self.failsafe_told |= bit;
                effects.push(Effect::Event {
                    kind: ArbiterEventKind::FailsafeHeld,
                    source: Some(source),
                    detail: detail.clone(),
                });
            }
            return refused(RefusalReason::AutopilotFailsafe, detail);
        }
        if !in_failsafe(vehicle.mode) {
            self.failsafe_told = 0;
        }
        if matches!(command, Command::Arm { force: true })
            && !matches!(source, CommandSource::Safety | CommandSource::Operator)
        {
            return refused(RefusalReason::Denied, "forced arm: safety or operator only");
        }
        let domain = kind.authority().unwrap_or(AuthorityDomain::Flight);
        if kind.is_authority_request() {
            return self.authority_request(now_ns, source, kind, domain, effects);
        }
        if let Claim::HeldBy(holder) = self.authority.claim(domain, source) {
            return refused(
                RefusalReason::NoAuthority,
                format!("{} authority held by {holder}", domain_name(domain)),
            );
        }
        let mut stream_until = None;
        if kind.is_setpoint() {
            let max_ns = self.policy.max_age_ns(source, sample.max_age_ms);
            match freshness::check(sample.header.stamp_ns, now_ns, max_ns) {
                Freshness::Stale { age_ns, max_ns } => {
                    return refused(
                        RefusalReason::Stale,
                        format!(
                            "{} ms old, max {} ms",
                            age_ns / NS_PER_MS,
                            max_ns / NS_PER_MS
                        ),
                    )
                }
                Freshness::Fresh { until_ns } => stream_until = Some(until_ns),
            }
        }
        if let Some(detail) = in_air::refusal(&command, &self.settings.servo_channels_in_flight) {
            if vehicle.in_air(&self.settings) {
                return refused(RefusalReason::InAir, detail);
            }
        }
        if let Command::SetHome {
            lat_deg,
            lon_deg,
            alt_msl_m,
        } = command
        {
            if let Err((reason, detail)) = self.home_check(lat_deg, lon_deg, alt_msl_m, vehicle) {
                return refused(reason, detail);
            }
        }
        let (command, limited) = match self.envelope(command, vehicle, source, effects) {
            Ok(x) => x,
            Err(detail) => {
                effects.push(Effect::Event {
                    kind: ArbiterEventKind::GeofenceRefused,
                    source: Some(source),
                    detail: detail.clone(),
                });
                return refused(RefusalReason::Geofence, detail);
            }
        };
        // The arbiter's own numbers are checked like a gateway's.
        if let Err(e) = command.validate() {
            return refused(e.reason(), format!("after limiting: {e}"));
        }
        let change = self.authority.act(domain, source, now_ns);
        if domain == AuthorityDomain::Flight {
            self.track_target(&command, source);
        }
        self.authority_changed(change, effects);
        match (stream_until, command) {
            (
                Some(until_ns),
                Command::VelocityNed {
                    vel_ned_mps,
                    yaw_rate_dps,
                },
            ) => {
                let moving = vel_ned_mps.iter().any(|v| v.abs() > 0.01)
                    || yaw_rate_dps.is_some_and(|r| r.abs() > 0.1);
                self.streams.fed(source, until_ns, moving);
            }
            _ if ends_stream(kind) => self.streams.end(),
            _ => {}
        }
        Outcome::Execute { command, limited }
    }

    fn authority_request(
        &mut self,
        now_ns: u64,
        source: CommandSource,
        kind: CommandKind,
        domain: AuthorityDomain,
        effects: &mut Vec<Effect>,
    ) -> Outcome {
        let name = domain_name(domain);
        let grab = matches!(
            kind,
            CommandKind::GrabFlightAuthority | CommandKind::GrabPayloadAuthority
        );
        if !grab {
            if domain == AuthorityDomain::Flight && self.authority.in_emergency() {
                return Outcome::Done {
                    detail: "emergency stop in force: safety keeps it".to_string(),
                };
            }
            return match self.authority.release(domain, source, now_ns) {
                Some(c) => {
                    effects.push(Effect::Authority(c));
                    Outcome::Done {
                        detail: format!("{name} authority released"),
                    }
                }
                None => Outcome::Done {
                    detail: format!("{name} authority was not held"),
                },
            };
        }
        let detail = match self.authority.claim(domain, source) {
            Claim::HeldBy(holder) => {
                return refused(
                    RefusalReason::NoAuthority,
                    format!("{name} authority held by {holder}"),
                )
            }
            Claim::Holds => format!("{name} authority already held"),
            Claim::Free => format!("{name} authority granted"),
            Claim::Outranks(holder) => format!("{name} authority taken from {holder}"),
        };
        let change = self.authority.act(domain, source, now_ns);
        self.authority_changed(change, effects);
        Outcome::Done { detail }
    }

    /// Publishes an authority change; a holder of a position target that lost flight
    /// authority by timeout or pre-emption is braked ([`Effect::TargetBrake`]).
    fn authority_changed(&mut self, change: Option<Change>, effects: &mut Vec<Effect>) {
        let Some(c) = change else { return };
        let lost = matches!(
            c.change,
            AuthorityChange::Timeout | AuthorityChange::Preempted
        );
        if c.domain == AuthorityDomain::Flight && lost && c.from.is_some() {
            if let Some(t) = self.position_target.filter(|t| Some(t.source) == c.from) {
                self.position_target = None;
                effects.push(Effect::TargetBrake { source: t.source });
            }
        }
        effects.push(Effect::Authority(c));
    }

    /// What is due at `now_ns` without a command: quiet holders lose authority, a
    /// stopped stream is braked.
    pub fn poll(&mut self, now_ns: u64) -> Vec<Effect> {
        let mut effects = Vec::new();
        for change in self.authority.poll(now_ns) {
            self.authority_changed(Some(change), &mut effects);
        }
        if let Some(stream) = self.streams.poll(now_ns) {
            effects.push(Effect::StaleBrake {
                source: stream.source,
            });
        }
        effects
    }

    /// When [`Arbiter::poll`] next has something to do.
    pub fn next_deadline_ns(&self) -> Option<u64> {
        [self.authority.next_deadline(), self.streams.deadline()]
            .into_iter()
            .flatten()
            .min()
    }

    /// The autopilot link went up or down. Down: nobody holds authority (an
    /// emergency stop stays in force). A setpoint stream is left to its deadline, so
    /// the brake is still attempted if the transport is open. Up: nothing old is
    /// re-sent.
    pub fn link_changed(&mut self, up: bool, now_ns: u64) -> Vec<Effect> {
        if up == self.link_up {
            return Vec::new();
        }
        self.link_up = up;
        if up {
            return vec![Effect::Event {
                kind: ArbiterEventKind::LinkRestored,
                source: None,
                detail: "autopilot link up; nothing old is re-sent".to_string(),
            }];
        }
        let mut effects: Vec<Effect> = self
            .authority
            .link_lost(now_ns)
            .into_iter()
            .map(Effect::Authority)
            .collect();
        effects.push(Effect::Event {
            kind: ArbiterEventKind::LinkLost,
            source: None,
            detail: "autopilot link down; commands refused".to_string(),
        });
        effects
    }
}
