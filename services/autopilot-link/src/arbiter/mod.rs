//! The command arbiter: every `VehicleCommand` that passed intake is decided here
//! before anything reaches MAVLink (../shared/DESIGN.md §3). Pure: no I/O, every
//! time is `CLOCK_MONOTONIC` ns passed in, so it is tested without sleeping.
//!
//! [`Arbiter::decide`] checks, in order, and the first failure refuses:
//!
//! | step | refusal |
//! |---|---|
//! | the sample decodes to a valid command (again: nothing bypasses the range checks) | `InvalidParameter` |
//! | no emergency stop in force, unless the sender is the safety source | `Emergency` |
//! | authority ([`authority`]: implicit grab, pre-emption by priority) | `NoAuthority` |
//! | a setpoint is fresh ([`freshness`]) | `Stale` |
//! | in the air ([`in_air`]): a motor kill is flagged as an emergency kill, no motor test, a servo only on a channel of `servo_channels_in_flight` | `InAir` |
//! | speed limits from the config (reduce → `Limited`) and the geofence ([`geofence`]: position targets refused, velocities reduced → `Limited`) | `Geofence` |
//!
//! Only a command that passes every step changes authority (so a refused command
//! from a higher-priority source pre-empts nobody) and feeds the setpoint stream.
//! An emergency stop always passes: safety takes flight authority and keeps it until
//! it releases it. [`Arbiter::poll`] does what is due without a command: quiet
//! holders lose authority, and a stopped setpoint stream is braked.
//!
//! In the air means armed and (position unknown or more than `in_air_alt_m` above
//! home or moving faster than `in_air_speed_mps`): conservative, an armed vehicle of
//! unknown position is in the air. A vehicle armed on a hill above home counts as
//! flying; `Disarm` (the autopilot's own landed check) remains for that case.

pub mod audit;
pub mod authority;
mod envelope;
pub mod freshness;
pub mod fence_stack;
pub mod geofence;
#[cfg(test)]
mod geofence_tests;
pub mod in_air;
#[cfg(test)]
mod in_air_tests;
#[cfg(test)]
mod tests;

use std::time::Duration;

use skymesh_ipc_types::{
    AckResult, ArbiterEventKind, AuthorityDomain, Command, CommandKind, CommandSource, FlightMode,
    RefusalReason, VehicleCommand, VehicleState,
};

use authority::{Authority, Change, Claim};
use freshness::{Freshness, FreshnessPolicy, Streams};
use fence_stack::FenceStack;
use geofence::Envelope;

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
}

/// Position and velocity of the vehicle, as far as the arbiter needs them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_rel_m: f32,
    pub vel_ned_mps: [f32; 3],
    /// How old the position fix is when the arbiter decides, s: the geofence adds it
    /// to the response time and refuses motion toward a boundary beyond
    /// [`geofence::MAX_FIX_AGE_S`].
    pub age_s: f32,
}

/// What the arbiter knows about the vehicle when it decides.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleView {
    pub armed: bool,
    pub mode: FlightMode,
    /// `None` when no position has been received or it is older than
    /// [`VehicleView::POSITION_MAX_AGE_NS`].
    pub position: Option<Kinematics>,
}

impl Default for VehicleView {
    /// Disarmed, mode unknown, no position.
    fn default() -> Self {
        VehicleView {
            armed: false,
            mode: FlightMode::Unknown,
            position: None,
        }
    }
}

impl VehicleView {
    /// An older position is not used for the geofence or the in-air test.
    pub const POSITION_MAX_AGE_NS: u64 = 2_000_000_000;

    pub fn new(armed: bool, mode: FlightMode, state: Option<&VehicleState>, now_ns: u64) -> Self {
        let position = state
            .filter(|s| {
                s.position_valid == 1
                    && now_ns.saturating_sub(s.position_stamp_ns) <= Self::POSITION_MAX_AGE_NS
            })
            .map(|s| Kinematics {
                lat_deg: s.lat_deg,
                lon_deg: s.lon_deg,
                alt_rel_m: s.alt_rel_m,
                vel_ned_mps: s.vel_ned_mps,
                age_s: now_ns.saturating_sub(s.position_stamp_ns) as f32 * 1e-9,
            });
        VehicleView {
            armed,
            mode,
            position,
        }
    }

    fn in_air(&self, s: &ArbiterSettings) -> bool {
        self.armed
            && self.position.is_none_or(|k| {
                let [n, e, d] = k.vel_ned_mps;
                k.alt_rel_m > s.in_air_alt_m
                    || n.hypot(e) > s.in_air_speed_mps
                    || d.abs() > s.in_air_speed_mps
            })
    }
}

/// What to do with a command.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Execute `command` (as the arbiter left it); `limited` says what it reduced.
    Execute {
        command: Command,
        limited: Option<String>,
    },
    /// Decided by the arbiter alone (authority requests): answer accepted.
    Done { detail: String },
    Refused {
        reason: RefusalReason,
        detail: String,
    },
}

/// Something the service must publish or do besides answering.
#[derive(Debug, Clone, PartialEq)]
pub enum Effect {
    /// Publish `AuthorityState` (and an `AuthorityChanged` event).
    Authority(Change),
    Event {
        kind: ArbiterEventKind,
        source: Option<CommandSource>,
        detail: String,
    },
    /// A geofence decision ([`Arbiter::set_geofence`]): an `ArbiterEvent` that echoes
    /// the `GeofenceSet`'s `request_id`.
    Fence {
        kind: ArbiterEventKind,
        source: Option<CommandSource>,
        request_id: u32,
        detail: String,
    },
    /// `source`'s setpoint stream stopped while moving: brake to a hover.
    StaleBrake { source: CommandSource },
}

/// The arbiter's answer to one command.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub outcome: Outcome,
    pub effects: Vec<Effect>,
}

impl Decision {
    pub fn result(&self) -> AckResult {
        match &self.outcome {
            Outcome::Execute {
                limited: Some(_), ..
            } => AckResult::Limited,
            Outcome::Execute { .. } | Outcome::Done { .. } => AckResult::Accepted,
            Outcome::Refused { .. } => AckResult::Refused,
        }
    }

    pub fn reason(&self) -> RefusalReason {
        match &self.outcome {
            Outcome::Refused { reason, .. } => *reason,
            _ => RefusalReason::None,
        }
    }

    pub fn detail(&self) -> &str {
        match &self.outcome {
            Outcome::Execute { limited, .. } => limited.as_deref().unwrap_or(""),
            Outcome::Done { detail } | Outcome::Refused { detail, .. } => detail,
        }
    }
}

fn refused(reason: RefusalReason, detail: impl Into<String>) -> Outcome {
    Outcome::Refused {
        reason,
        detail: detail.into(),
    }
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
            && kind != CommandKind::EmergencyStop
        {
            return refused(
                RefusalReason::Emergency,
                "emergency stop: only safety may command",
            );
        }
        if kind == CommandKind::EmergencyStop {
            effects.extend(self.authority.emergency(now_ns).map(Effect::Authority));
            self.streams.end();
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
        effects.extend(
            self.authority
                .act(domain, source, now_ns)
                .map(Effect::Authority),
        );
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
        effects.extend(
            self.authority
                .act(domain, source, now_ns)
                .map(Effect::Authority),
        );
        Outcome::Done { detail }
    }

    /// What is due at `now_ns` without a command: quiet holders lose authority, a
    /// stopped stream is braked.
    pub fn poll(&mut self, now_ns: u64) -> Vec<Effect> {
        let mut effects: Vec<Effect> = self
            .authority
            .poll(now_ns)
            .into_iter()
            .map(Effect::Authority)
            .collect();
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
