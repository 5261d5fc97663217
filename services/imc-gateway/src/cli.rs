//! The `skymesh-imc` command line (clap), and what each command sends.
//!
//! In the library so the mapping is unit-tested; the binary
//! (`src/bin/skymesh-imc.rs`) does the I/O.

use std::net::SocketAddr;

use clap::{Parser, Subcommand, ValueEnum};
use imc_proto::{ChannelOp, LcdOperation, Message, PowerOp, RemoteActionsOp, ZoomAction};

/// Parses `0x2c01`, `0X2C01` or decimal.
pub fn parse_u16(s: &str) -> Result<u16, String> {
    let parsed = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u16::from_str_radix(hex, 16),
        None => s.parse(),
    };
    parsed.map_err(|e| format!("`{s}` is not a number 0..=65535 (decimal or 0x hex): {e}"))
}

#[derive(Debug, Parser)]
#[command(
    name = "skymesh-imc",
    version,
    about = "Poke an IMC gateway as Neptus or DUNE would: send one IMC message over UDP and print what comes back"
)]
pub struct Cli {
    /// The gateway's IMC address (`listen` in imc-gateway.toml).
    #[arg(long, env = "SKYMESH_IMC_ADDR", default_value = "127.0.0.1:6002")]
    pub to: SocketAddr,
    /// Seconds to keep printing what arrives after the command.
    #[arg(long, default_value_t = 1.0)]
    pub wait: f64,
    /// Our IMC address (header `src`), decimal or 0x hex.
    #[arg(long, value_parser = parse_u16, default_value = "0x4001")]
    pub src: u16,
    #[arg(long, default_value_t = 0)]
    pub src_ent: u8,
    /// The gateway's IMC address (header `dst`); 0xFFFF reaches any system.
    #[arg(long, value_parser = parse_u16, default_value = "0xFFFF")]
    pub dst: u16,
    #[arg(long, default_value_t = 255)]
    pub dst_ent: u8,
    /// Also print Heartbeat and Announce messages.
    #[arg(long)]
    pub all: bool,
    #[command(subcommand)]
    pub cmd: Cmd,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ChannelArg {
    On,
    Off,
    Toggle,
    SchedOn,
    SchedOff,
    SchedReset,
    Save,
    Restart,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PowerArg {
    /// Power the companion computer down (after its configured delay).
    Down,
    /// Power down at a Unix time.
    SchedDown,
    /// Abort a pending power down.
    Abort,
    Up,
    /// Power up at a Unix time.
    SchedUp,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ZoomArg {
    Reset,
    In,
    Out,
    Stop,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LcdArg {
    Off,
    On,
    Clear,
    Write0,
    Write1,
}

#[derive(Debug, Subcommand)]
pub enum LedCmd {
    /// SetLedBrightness: answered with LedBrightness.
    Set { name: String, value: u8 },
    /// QueryLedBrightness: answered with LedBrightness.
    Query { name: String },
}

#[derive(Debug, Subcommand)]
pub enum GpioCmd {
    /// GpioStateSet: answered with GpioState.
    Set { name: String, value: u8 },
    /// GpioStateGet: answered with GpioState.
    Get { name: String },
}

#[derive(Debug, Subcommand)]
pub enum Cmd {
    /// LEDs.
    Led {
        #[command(subcommand)]
        op: LedCmd,
    },
    /// GPIO lines.
    Gpio {
        #[command(subcommand)]
        op: GpioCmd,
    },
    /// PowerChannelControl; SECS for sched-on / sched-off (seconds from now).
    PowerChannel {
        name: String,
        op: ChannelArg,
        secs: Option<f64>,
    },
    /// QueryPowerChannelState: one PowerChannelState per channel.
    QueryPower,
    /// PowerOperation for the companion computer; UNIX_TIME for sched-down / sched-up.
    Power {
        op: PowerArg,
        unix_time: Option<f64>,
    },
    /// SetPWM (period and duty cycle in µs): answered with PWM once accepted.
    Pwm { id: u8, period: u32, duty: u32 },
    /// SetServoPosition (radians, −π/2..π/2).
    #[command(allow_negative_numbers = true)]
    Servo { id: u8, rad: f32 },
    /// SetControlSurfaceDeflection (radians).
    #[command(allow_negative_numbers = true)]
    Surface { id: u8, rad: f32 },
    /// SetThrusterActuation (0..1).
    #[command(allow_negative_numbers = true)]
    Thruster { id: u8, value: f32 },
    /// ButtonEvent (1 press, 0 release).
    Button { id: u8, value: u8 },
    /// CameraZoom; LEVEL (0..255) with stop = go to that absolute level.
    Zoom {
        id: u8,
        action: ZoomArg,
        level: Option<u8>,
    },
    /// LcdControl.
    Lcd { op: LcdArg, text: Option<String> },
    /// RemoteActions, e.g. "Forward=0.5;Yaw=0"; with --rate, streamed for --duration.
    RemoteActions {
        actions: String,
        /// Messages per second (streams instead of sending once).
        #[arg(long)]
        rate: Option<f64>,
        /// Seconds to stream.
        #[arg(long, default_value_t = 5.0)]
        duration: f64,
    },
    /// RemoteActionsRequest QUERY: answered with the action table (REPORT).
    QueryActions,
    /// Heartbeat: the gateway then heartbeats us for 30 s.
    Heartbeat,
    /// Send a Heartbeat, then print everything that arrives (Ctrl-C to stop).
    Listen,
}

fn channel_op(op: ChannelArg) -> ChannelOp {
    match op {
        ChannelArg::On => ChannelOp::TurnOn,
        ChannelArg::Off => ChannelOp::TurnOff,
        ChannelArg::Toggle => ChannelOp::Toggle,
        ChannelArg::SchedOn => ChannelOp::ScheduleOn,
        ChannelArg::SchedOff => ChannelOp::ScheduleOff,
        ChannelArg::SchedReset => ChannelOp::ScheduleReset,
        ChannelArg::Save => ChannelOp::Save,
        ChannelArg::Restart => ChannelOp::Restart,
    }
}

/// The message a command sends.
pub fn message_for(cmd: &Cmd) -> Result<Message, String> {
    Ok(match cmd {
        Cmd::Led { op } => match op {
            LedCmd::Set { name, value } => Message::SetLedBrightness {
                name: name.clone(),
                value: *value,
            },
            LedCmd::Query { name } => Message::QueryLedBrightness { name: name.clone() },
        },
        Cmd::Gpio { op } => match op {
            GpioCmd::Set { name, value } => Message::GpioStateSet {
                name: name.clone(),
                value: *value,
            },
            GpioCmd::Get { name } => Message::GpioStateGet { name: name.clone() },
        },
        Cmd::PowerChannel { name, op, secs } => {
            let scheduled = matches!(op, ChannelArg::SchedOn | ChannelArg::SchedOff);
            let sched_time = match (scheduled, secs) {
                (true, Some(s)) if s.is_finite() && *s >= 0.0 => *s,
                (true, _) => return Err(format!("{op:?} needs SECS (seconds from now, ≥ 0)")),
                (false, _) => 0.0,
            };
            Message::PowerChannelControl {
                name: name.clone(),
                op: channel_op(*op),
                sched_time,
            }
        }
        Cmd::QueryPower => Message::QueryPowerChannelState,
        Cmd::Power { op, unix_time } => {
            let (op, needs_time) = match op {
                PowerArg::Down => (PowerOp::PowerDown, false),
                PowerArg::SchedDown => (PowerOp::SchedulePowerDown, true),
                PowerArg::Abort => (PowerOp::PowerDownAborted, false),
                PowerArg::Up => (PowerOp::PowerUp, false),
                PowerArg::SchedUp => (PowerOp::SchedulePowerUp, true),
            };
            let sched_time = match (needs_time, unix_time) {
                (true, Some(t)) if t.is_finite() => *t,
                (true, _) => return Err(format!("{op:?} needs UNIX_TIME")),
                (false, _) => 0.0,
            };
            Message::PowerOperation {
                op,
                time_remain: 0.0,
                sched_time,
            }
        }
        Cmd::Pwm { id, period, duty } => Message::SetPwm {
            id: *id,
            period: *period,
            duty_cycle: *duty,
        },
        Cmd::Servo { id, rad } => Message::SetServoPosition {
            id: *id,
            value: *rad,
        },
        Cmd::Surface { id, rad } => Message::SetControlSurfaceDeflection {
            id: *id,
            angle: *rad,
        },
        Cmd::Thruster { id, value } => Message::SetThrusterActuation {
            id: *id,
            value: *value,
        },
        Cmd::Button { id, value } => Message::ButtonEvent {
            button: *id,
            value: *value,
        },
        Cmd::Zoom { id, action, level } => Message::CameraZoom {
            id: *id,
            zoom: level.unwrap_or(0),
            action: match action {
                ZoomArg::Reset => ZoomAction::Reset,
                ZoomArg::In => ZoomAction::In,
                ZoomArg::Out => ZoomAction::Out,
                ZoomArg::Stop => ZoomAction::Stop,
            },
        },
        Cmd::Lcd { op, text } => {
            let op = match op {
                LcdArg::Off => LcdOperation::TurnOff,
                LcdArg::On => LcdOperation::TurnOn,
                LcdArg::Clear => LcdOperation::Clear,
                LcdArg::Write0 => LcdOperation::Write0,
                LcdArg::Write1 => LcdOperation::Write1,
            };
            Message::LcdControl {
                op,
                text: text.clone().unwrap_or_default(),
            }
        }
        Cmd::RemoteActions { actions, .. } => Message::RemoteActions {
            actions: actions.clone(),
        },
        Cmd::QueryActions => Message::RemoteActionsRequest {
            op: RemoteActionsOp::Query,
            actions: String::new(),
        },
        Cmd::Heartbeat | Cmd::Listen => Message::Heartbeat,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(args: &[&str]) -> Result<Message, String> {
        let mut full = vec!["skymesh-imc"];
        full.extend_from_slice(args);
        let cli = Cli::try_parse_from(full).map_err(|e| e.to_string())?;
        message_for(&cli.cmd)
    }

    #[test]
    fn commands_map_to_their_messages() {
        assert_eq!(
            msg(&["led", "set", "status", "200"]).unwrap(),
            Message::SetLedBrightness {
                name: "status".into(),
                value: 200
            }
        );
        assert_eq!(
            msg(&["power-channel", "payload", "sched-on", "5"]).unwrap(),
            Message::PowerChannelControl {
                name: "payload".into(),
                op: ChannelOp::ScheduleOn,
                sched_time: 5.0
            }
        );
        assert!(msg(&["power-channel", "payload", "sched-on"]).is_err());
        assert_eq!(
            msg(&["servo", "0", "-1.2"]).unwrap(),
            Message::SetServoPosition { id: 0, value: -1.2 }
        );
        assert_eq!(
            msg(&["zoom", "1", "stop", "128"]).unwrap(),
            Message::CameraZoom {
                id: 1,
                zoom: 128,
                action: ZoomAction::Stop
            }
        );
        assert_eq!(
            msg(&["remote-actions", "Forward=0.5;Yaw=0", "--rate", "10"]).unwrap(),
            Message::RemoteActions {
                actions: "Forward=0.5;Yaw=0".into()
            }
        );
        assert_eq!(
            msg(&["lcd", "write0", "hello"]).unwrap(),
            Message::LcdControl {
                op: LcdOperation::Write0,
                text: "hello".into()
            }
        );
        assert!(msg(&["power", "sched-down"]).is_err());
        assert!(msg(&["led", "set", "status", "300"]).is_err());
    }

    #[test]
    fn addresses_take_hex_or_decimal() {
        assert_eq!(parse_u16("0x2c01"), Ok(0x2c01));
        assert_eq!(parse_u16("11265"), Ok(0x2c01));
        assert!(parse_u16("0x10000").is_err());
        let cli = Cli::try_parse_from(["skymesh-imc", "--dst", "0x2C01", "heartbeat"]).unwrap();
        assert_eq!(cli.dst, 0x2c01);
        assert_eq!(cli.src, 0x4001);
    }
}
