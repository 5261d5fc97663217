//! Teleoperation (pure): IMC `RemoteActions` → velocity setpoints and button events.
//!
//! A `RemoteActions` message is a TupleList `Name=value;…` of the actions the
//! gateway reported for `RemoteActionsRequest` QUERY (`[teleop] actions`). As the
//! IMC document says, an action missing from a message is 0. The Axis actions with a
//! role (`forward`, `right`, `up`, `yaw`) become one `VelocityNed` with a yaw rate:
//! forward/right are body-frame and rotated into north/east with the vehicle's yaw.
//! The setpoints carry a short maximum age, so when the operator stops sending the
//! arbiter brakes. Button actions become presses (0 → non-zero) and releases
//! (non-zero → 0), tracked per peer.

use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use imc_proto::{parse_tuple_list, TupleListError};
use skymesh_ipc_types::{
    Button, ButtonEventKind, Command, FlightMode, VehicleState, VehicleStatus,
};

/// The type of a remote action, as reported to peers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ActionKind {
    Axis,
    Hat,
    Button,
}

impl ActionKind {
    pub fn as_str(self) -> &'static str {
        match self {
            ActionKind::Axis => "Axis",
            ActionKind::Hat => "Hat",
            ActionKind::Button => "Button",
        }
    }

    /// `Axis`, `Hat` or `Button`, any case.
    pub fn parse(s: &str) -> Option<ActionKind> {
        [ActionKind::Axis, ActionKind::Hat, ActionKind::Button]
            .into_iter()
            .find(|k| k.as_str().eq_ignore_ascii_case(s))
    }
}

/// `[teleop]` of the config, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct TeleopSettings {
    /// The action table, in the configured order.
    pub actions: Vec<(String, ActionKind)>,
    /// Axis action flying forward (body frame); `None` = unused.
    pub forward: Option<String>,
    pub right: Option<String>,
    pub up: Option<String>,
    pub yaw: Option<String>,
    pub max_speed_mps: f32,
    pub max_climb_mps: f32,
    pub max_yaw_rate_dps: f32,
    /// Maximum age of each velocity setpoint at the arbiter.
    pub max_age_ms: u32,
    /// Send `SetMode(Guided)` on the first non-zero axis when flying in another mode.
    pub switch_to_guided: bool,
    /// Button actions and the skymesh button each presses.
    pub buttons: Vec<(String, Button)>,
}

impl TeleopSettings {
    /// The action table as the TupleList of a `RemoteActionsRequest` REPORT.
    pub fn actions_text(&self) -> String {
        let pairs: Vec<(&str, &str)> = self
            .actions
            .iter()
            .map(|(name, kind)| (name.as_str(), kind.as_str()))
            .collect();
        imc_proto::format_tuple_list(&pairs)
    }

    fn kind_of(&self, name: &str) -> Option<ActionKind> {
        self.actions
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, k)| *k)
    }
}

/// What the gateway knows of the vehicle: the latest state and status samples.
#[derive(Debug, Clone, Copy, Default)]
pub struct VehicleView {
    pub state: Option<VehicleState>,
    pub status: Option<VehicleStatus>,
}

/// Armed and above this height or faster than this speed: in the air (the arbiter's
/// rule, conservative: an armed vehicle of unknown position is in the air).
const IN_AIR_ALT_M: f32 = 0.5;
const IN_AIR_SPEED_MPS: f32 = 0.5;

impl VehicleView {
    /// Yaw (rad, NED) once an attitude has arrived.
    pub fn yaw_rad(&self) -> Option<f32> {
        self.state
            .filter(|s| s.attitude_valid != 0 && s.yaw_rad.is_finite())
            .map(|s| s.yaw_rad)
    }

    pub fn is_armed(&self) -> bool {
        self.status.is_some_and(|s| s.is_armed())
    }

    pub fn mode(&self) -> FlightMode {
        self.status.map_or(FlightMode::Unknown, |s| s.flight_mode())
    }

    pub fn in_air(&self) -> bool {
        if !self.is_armed() {
            return false;
        }
        match self.state {
            Some(s) if s.position_valid != 0 => {
                let [n, e, d] = s.vel_ned_mps;
                s.alt_rel_m > IN_AIR_ALT_M
                    || n.hypot(e) > IN_AIR_SPEED_MPS
                    || d.abs() > IN_AIR_SPEED_MPS
            }
            _ => true,
        }
    }
}

/// Why a `RemoteActions` message was dropped (the whole message).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TeleopError {
    #[error("the action list cannot be read: {0}")]
    Parse(#[from] TupleListError),
    #[error("action {action}: {value:?} is not a finite number")]
    NotANumber { action: String, value: String },
    #[error("axis {action}: {value} is outside -1..1")]
    OutOfRange { action: String, value: f32 },
    #[error("no vehicle attitude yet: cannot turn body-frame axes into north/east")]
    NoVehicleState,
}

impl TeleopError {
    /// The `skymesh_imc_dropped_total` reason.
    pub fn reason(&self) -> &'static str {
        match self {
            TeleopError::Parse(_) | TeleopError::NotANumber { .. } => "invalid_value",
            TeleopError::OutOfRange { .. } => "out_of_range",
            TeleopError::NoVehicleState => "no_vehicle_state",
        }
    }
}

/// What one `RemoteActions` message asks for.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TeleopOutput {
    /// Send `SetMode(Guided)` before the setpoint.
    pub set_guided: bool,
    /// A `VelocityNed` setpoint (with yaw rate) to send.
    pub velocity: Option<Command>,
    /// Button presses and releases, in the configured order.
    pub buttons: Vec<(Button, ButtonEventKind)>,
    /// Action names seen for the first time that are not in the action table.
    pub new_unknown: Vec<String>,
}

/// Unknown action names remembered (so each is counted once); beyond this many,
/// further new names are not counted.
const MAX_UNKNOWN_NAMES: usize = 64;
/// At most one `SetMode(Guided)` per this period.
pub const GUIDED_REQUEST_EVERY: Duration = Duration::from_secs(2);

/// Teleoperation state: buttons held per peer, whether the last setpoint moved.
#[derive(Debug)]
pub struct Teleop {
    settings: TeleopSettings,
    /// Button actions currently held, per peer.
    held: HashMap<SocketAddr, HashSet<String>>,
    /// The last setpoint sent was non-zero: the next message sends one even without
    /// an axis action, so the vehicle is told to stop.
    moving: bool,
    last_guided_request: Option<Instant>,
    unknown: HashSet<String>,
}

impl Teleop {
    pub fn new(settings: TeleopSettings) -> Self {
        Teleop {
            settings,
            held: HashMap::new(),
            moving: false,
            last_guided_request: None,
            unknown: HashSet::new(),
        }
    }

    pub fn settings(&self) -> &TeleopSettings {
        &self.settings
    }

    /// One `RemoteActions` message from `peer`.
    pub fn on_remote_actions(
        &mut self,
        peer: SocketAddr,
        text: &str,
        vehicle: &VehicleView,
        now: Instant,
    ) -> Result<TeleopOutput, TeleopError> {
        let mut out = TeleopOutput::default();
        let mut values: HashMap<String, f32> = HashMap::new();
        let mut unknown = Vec::new();
        for (name, raw) in parse_tuple_list(text)? {
            let value = raw
                .parse::<f32>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| TeleopError::NotANumber {
                    action: name.clone(),
                    value: raw.clone(),
                })?;
            match self.settings.kind_of(&name) {
                None => unknown.push(name),
                Some(ActionKind::Axis) if !(-1.0..=1.0).contains(&value) => {
                    return Err(TeleopError::OutOfRange {
                        action: name,
                        value,
                    })
                }
                Some(_) => {
                    values.insert(name, value);
                }
            }
        }

        let s = &self.settings;
        let role = |r: &Option<String>| r.as_ref().and_then(|n| values.get(n)).copied();
        let axes = [role(&s.forward), role(&s.right), role(&s.up), role(&s.yaw)];
        let has_axis = axes.iter().any(Option::is_some);
        let [fwd, right, up, yaw] = axes.map(|a| a.unwrap_or(0.0));
        let nonzero = [fwd, right, up, yaw].iter().any(|v| *v != 0.0);
        if has_axis || self.moving {
            let psi = if nonzero {
                vehicle.yaw_rad().ok_or(TeleopError::NoVehicleState)?
            } else {
                0.0
            };
            let (sin, cos) = psi.sin_cos();
            let (f, r) = (fwd * s.max_speed_mps, right * s.max_speed_mps);
            out.velocity = Some(Command::VelocityNed {
                vel_ned_mps: [f * cos - r * sin, f * sin + r * cos, -up * s.max_climb_mps],
                yaw_rate_dps: Some(yaw * s.max_yaw_rate_dps),
            });
            let due = self
                .last_guided_request
                .is_none_or(|t| now.duration_since(t) >= GUIDED_REQUEST_EVERY);
            if nonzero
                && s.switch_to_guided
                && vehicle.in_air()
                && vehicle.mode() != FlightMode::Guided
                && due
            {
                out.set_guided = true;
                self.last_guided_request = Some(now);
            }
            self.moving = nonzero;
        }

        let held = self.held.entry(peer).or_default();
        for (name, button) in &s.buttons {
            let down = values.get(name).is_some_and(|v| *v != 0.0);
            if down && held.insert(name.clone()) {
                out.buttons.push((*button, ButtonEventKind::Press));
            } else if !down && held.remove(name) {
                out.buttons.push((*button, ButtonEventKind::Release));
            }
        }

        for name in unknown {
            if self.unknown.len() < MAX_UNKNOWN_NAMES && self.unknown.insert(name.clone()) {
                out.new_unknown.push(name);
            }
        }
        Ok(out)
    }

    /// Forgets a peer that went quiet; returns the buttons it still held (to release).
    pub fn forget(&mut self, peer: SocketAddr) -> Vec<Button> {
        let Some(held) = self.held.remove(&peer) else {
            return Vec::new();
        };
        self.settings
            .buttons
            .iter()
            .filter(|(name, _)| held.contains(name))
            .map(|(_, b)| *b)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> TeleopSettings {
        let kinds = [
            ("Forward", ActionKind::Axis),
            ("Right", ActionKind::Axis),
            ("Up", ActionKind::Axis),
            ("Yaw", ActionKind::Axis),
            ("Fly", ActionKind::Button),
            ("A", ActionKind::Button),
            ("PanTilt", ActionKind::Hat),
        ];
        TeleopSettings {
            actions: kinds.iter().map(|(n, k)| (n.to_string(), *k)).collect(),
            forward: Some("Forward".into()),
            right: Some("Right".into()),
            up: Some("Up".into()),
            yaw: Some("Yaw".into()),
            max_speed_mps: 2.0,
            max_climb_mps: 1.0,
            max_yaw_rate_dps: 45.0,
            max_age_ms: 500,
            switch_to_guided: false,
            buttons: vec![("Fly".into(), Button::Fly), ("A".into(), Button::A)],
        }
    }

    fn peer(port: u16) -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], port))
    }

    fn flying(yaw_deg: f32, mode: FlightMode) -> VehicleView {
        VehicleView {
            state: Some(VehicleState {
                attitude_valid: 1,
                position_valid: 1,
                yaw_rad: yaw_deg.to_radians(),
                alt_rel_m: 10.0,
                ..Default::default()
            }),
            status: Some(VehicleStatus {
                armed: 1,
                mode: mode.to_wire(),
                ..Default::default()
            }),
        }
    }

    fn velocity(out: &TeleopOutput) -> ([f32; 3], f32) {
        match out.velocity {
            Some(Command::VelocityNed {
                vel_ned_mps,
                yaw_rate_dps: Some(r),
            }) => (vel_ned_mps, r),
            ref other => panic!("no velocity setpoint: {other:?}"),
        }
    }

    fn close(a: [f32; 3], b: [f32; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4)
    }

    #[test]
    fn body_axes_are_rotated_by_the_vehicle_yaw_and_scaled() {
        let mut t = Teleop::new(settings());
        let now = Instant::now();
        // Facing east: forward is east, right is south.
        let v = flying(90.0, FlightMode::Guided);
        let out = t
            .on_remote_actions(peer(1), "Forward=0.5;Right=0.25;Up=1;Yaw=-0.5", &v, now)
            .unwrap();
        let (vel, rate) = velocity(&out);
        assert!(close(vel, [-0.5, 1.0, -1.0]), "{vel:?}");
        assert_eq!(rate, -22.5);
        assert!(out.velocity.unwrap().validate().is_ok());
        // Facing north, commas as separators, missing actions are 0.
        let v = flying(0.0, FlightMode::Guided);
        let out = t.on_remote_actions(peer(1), "Forward=1", &v, now).unwrap();
        assert!(close(velocity(&out).0, [2.0, 0.0, 0.0]));
        let out = t
            .on_remote_actions(peer(1), "Right=1,Yaw=0", &v, now)
            .unwrap();
        assert!(close(velocity(&out).0, [0.0, 2.0, 0.0]));
    }

    #[test]
    fn a_zero_setpoint_follows_a_moving_one_and_buttons_alone_claim_nothing() {
        let mut t = Teleop::new(settings());
        let now = Instant::now();
        let v = flying(0.0, FlightMode::Guided);
        let out = t.on_remote_actions(peer(1), "Fly=0", &v, now).unwrap();
        assert_eq!(out.velocity, None, "buttons only: no setpoint");
        t.on_remote_actions(peer(1), "Forward=1", &v, now).unwrap();
        let out = t.on_remote_actions(peer(1), "Fly=0", &v, now).unwrap();
        assert!(close(velocity(&out).0, [0.0; 3]), "stop after moving");
        let out = t.on_remote_actions(peer(1), "A=0", &v, now).unwrap();
        assert_eq!(out.velocity, None, "stopped already");
    }

    #[test]
    fn bad_values_drop_the_whole_message() {
        let mut t = Teleop::new(settings());
        let now = Instant::now();
        let v = flying(0.0, FlightMode::Guided);
        for (text, reason) in [
            ("Forward=fast", "invalid_value"),
            ("Forward=NaN", "invalid_value"),
            ("Forward=inf", "invalid_value"),
            ("Fly=1;Up=1.5", "out_of_range"),
            ("Forward", "invalid_value"),
        ] {
            let e = t.on_remote_actions(peer(1), text, &v, now).unwrap_err();
            assert_eq!(e.reason(), reason, "{text}: {e}");
        }
        // Nothing of the dropped "Fly=1;Up=1.5" was applied: Fly is not held.
        let out = t.on_remote_actions(peer(1), "Fly=1", &v, now).unwrap();
        assert_eq!(out.buttons, vec![(Button::Fly, ButtonEventKind::Press)]);
        // Without an attitude, moving is refused but stopping is not.
        let e = t
            .on_remote_actions(peer(1), "Forward=1", &VehicleView::default(), now)
            .unwrap_err();
        assert_eq!(e.reason(), "no_vehicle_state");
        let out = t
            .on_remote_actions(peer(1), "Forward=0", &VehicleView::default(), now)
            .unwrap();
        assert!(close(velocity(&out).0, [0.0; 3]));
    }

    #[test]
    fn buttons_press_and_release_on_transitions_per_peer() {
        let mut t = Teleop::new(settings());
        let now = Instant::now();
        let v = flying(0.0, FlightMode::Guided);
        let press = |b| (b, ButtonEventKind::Press);
        let release = |b| (b, ButtonEventKind::Release);
        let out = t.on_remote_actions(peer(1), "Fly=1;A=1", &v, now).unwrap();
        assert_eq!(out.buttons, vec![press(Button::Fly), press(Button::A)]);
        let out = t.on_remote_actions(peer(1), "Fly=1;A=1", &v, now).unwrap();
        assert!(out.buttons.is_empty(), "held, no repeat");
        // Another peer has its own state.
        let out = t.on_remote_actions(peer(2), "A=1", &v, now).unwrap();
        assert_eq!(out.buttons, vec![press(Button::A)]);
        // Missing means 0: Fly and A released.
        let out = t.on_remote_actions(peer(1), "Forward=0", &v, now).unwrap();
        assert_eq!(out.buttons, vec![release(Button::Fly), release(Button::A)]);
        assert_eq!(t.forget(peer(2)), vec![Button::A]);
        assert!(t.forget(peer(2)).is_empty());
    }

    #[test]
    fn unknown_actions_are_ignored_and_reported_once() {
        let mut t = Teleop::new(settings());
        let now = Instant::now();
        let v = flying(0.0, FlightMode::Guided);
        let out = t
            .on_remote_actions(peer(1), "Lights=1;Forward=0.1;PanTilt=3", &v, now)
            .unwrap();
        assert_eq!(out.new_unknown, vec!["Lights".to_string()]);
        assert!(out.velocity.is_some());
        let out = t.on_remote_actions(peer(1), "Lights=0", &v, now).unwrap();
        assert!(out.new_unknown.is_empty());
    }

    #[test]
    fn guided_is_requested_only_when_configured_flying_and_not_guided() {
        let mut s = settings();
        let now = Instant::now();
        let mut t = Teleop::new(s.clone());
        let out = t
            .on_remote_actions(peer(1), "Forward=1", &flying(0.0, FlightMode::Auto), now)
            .unwrap();
        assert!(!out.set_guided, "off by default");

        s.switch_to_guided = true;
        let mut t = Teleop::new(s);
        let auto = flying(0.0, FlightMode::Auto);
        assert!(
            !t.on_remote_actions(peer(1), "Forward=0", &auto, now)
                .unwrap()
                .set_guided,
            "zero axes do not switch"
        );
        assert!(
            t.on_remote_actions(peer(1), "Forward=1", &auto, now)
                .unwrap()
                .set_guided
        );
        let soon = now + Duration::from_millis(500);
        assert!(
            !t.on_remote_actions(peer(1), "Forward=1", &auto, soon)
                .unwrap()
                .set_guided,
            "at most every 2 s"
        );
        let later = now + GUIDED_REQUEST_EVERY;
        assert!(
            t.on_remote_actions(peer(1), "Forward=1", &auto, later)
                .unwrap()
                .set_guided
        );
        let guided = flying(0.0, FlightMode::Guided);
        let much_later = later + GUIDED_REQUEST_EVERY;
        assert!(
            !t.on_remote_actions(peer(1), "Forward=1", &guided, much_later)
                .unwrap()
                .set_guided
        );
        let mut on_ground = flying(0.0, FlightMode::Loiter);
        if let Some(st) = on_ground.state.as_mut() {
            st.alt_rel_m = 0.0;
        }
        assert!(
            !t.on_remote_actions(peer(1), "Forward=1", &on_ground, much_later)
                .unwrap()
                .set_guided,
            "not on the ground"
        );
    }

    #[test]
    fn the_report_lists_the_configured_actions() {
        assert_eq!(ActionKind::parse("button"), Some(ActionKind::Button));
        assert_eq!(ActionKind::parse("Slider"), None);
        let text = settings().actions_text();
        let pairs = parse_tuple_list(&text).unwrap();
        assert_eq!(pairs.len(), 7);
        assert_eq!(pairs[6], ("PanTilt".to_string(), "Hat".to_string()));
    }
}
