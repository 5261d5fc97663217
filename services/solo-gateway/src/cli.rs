//! The `skymesh-solo` command line (clap), and what each command sends.
//!
//! In the library so the mapping is unit-tested; the binary
//! (`src/bin/skymesh-solo.rs`) does the I/O.

use std::net::SocketAddr;

use clap::{Parser, Subcommand, ValueEnum};
use skymesh_ipc_types::{Button, ButtonEventKind};
use solo_proto::{shots, ButtonSetting, Location, SoloMessage};

use crate::describe::parse_shot;

#[derive(Debug, Parser)]
#[command(
    name = "skymesh-solo",
    version,
    about = "Fly Solo shots without the phone app: talks to solo-gateway as the 3DR Solo app does"
)]
pub struct Cli {
    /// solo-gateway's app address (`listen` in solo-gateway.toml).
    #[arg(long, env = "SKYMESH_SOLO_ADDR", default_value = "127.0.0.1:5507")]
    pub addr: SocketAddr,
    /// Seconds to stay connected after the command, printing what arrives.
    #[arg(long, default_value_t = 1.0)]
    pub wait: f64,
    #[command(subcommand)]
    pub cmd: Cmd,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum AB {
    A,
    B,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Preference {
    Hold,
    Free,
    Leash,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Record {
    On,
    Off,
    Toggle,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OnOff {
    On,
    Off,
}

#[derive(Debug, Subcommand)]
pub enum Cmd {
    /// Enter a shot: selfie, orbit, cablecam, follow, multipoint, … none, or its index.
    Shot { shot: String },
    /// Send a location (orbit ROI, selfie points, …): degrees, degrees, metres above home.
    #[command(allow_negative_numbers = true)]
    Location { lat: f64, lon: f64, alt: f32 },
    /// Record the vehicle's position (cable cam points).
    Record,
    /// Set the shot's cruise speed (SHOT_OPTIONS).
    #[command(allow_negative_numbers = true)]
    Options {
        #[arg(long)]
        speed: f32,
    },
    /// Cable cam options.
    #[command(allow_negative_numbers = true)]
    CableOptions {
        #[arg(long, action = clap::ArgAction::Set)]
        interpolate: bool,
        /// Yaw direction clockwise.
        #[arg(long, action = clap::ArgAction::Set)]
        cw: bool,
        #[arg(long)]
        speed: f32,
    },
    /// Follow options (FOLLOW_OPTIONS_V2).
    #[command(allow_negative_numbers = true)]
    FollowOptions {
        #[arg(long)]
        speed: f32,
        #[arg(long, action = clap::ArgAction::Set, default_value_t = true)]
        look_at: bool,
        #[arg(long, value_enum, default_value_t = Preference::Hold)]
        preference: Preference,
    },
    /// Pause or resume the shot (SOLO_PAUSE).
    Pause,
    /// Enter Follow and stream this position (moving by the given velocity) to the
    /// follow stream, holding the app connection, until --duration or Ctrl-C.
    #[command(allow_negative_numbers = true)]
    Follow {
        lat: f64,
        lon: f64,
        alt: f32,
        /// Datagrams per second.
        #[arg(long, default_value_t = 25.0)]
        rate: f64,
        #[arg(long, default_value_t = 0.0)]
        velocity_north: f64,
        #[arg(long, default_value_t = 0.0)]
        velocity_east: f64,
        /// Seconds to stream (default: until Ctrl-C).
        #[arg(long)]
        duration: Option<f64>,
        /// Follow-stream address (default: the --addr host, port 14558).
        #[arg(long)]
        udp: Option<SocketAddr>,
    },
    /// Press a controller button (a ButtonEvent on the bus, domain from SKYMESH_DOMAIN).
    Button {
        /// power, fly, rtl, loiter, a, b, preset1, preset2, camera_click, pause.
        button: String,
        /// press, release, click_release, hold, long_hold, double_click.
        #[arg(default_value = "press")]
        event: String,
        #[arg(long, default_value_t = 1)]
        vehicle: u8,
    },
    /// Ask which shot or mode button A or B starts.
    GetButton {
        #[arg(value_enum)]
        button: AB,
    },
    /// Map button A or B to a shot (--shot NAME) or a flight mode (--mode N).
    SetButton {
        #[arg(value_enum)]
        button: AB,
        #[arg(long, conflicts_with = "mode", required_unless_present = "mode")]
        shot: Option<String>,
        #[arg(long)]
        mode: Option<i32>,
    },
    /// GoPro control.
    Gopro {
        #[command(subcommand)]
        cmd: GoPro,
    },
    /// Stay connected and print everything until Ctrl-C.
    Listen,
}

#[derive(Debug, Subcommand)]
pub enum GoPro {
    /// Start, stop or toggle recording.
    Record {
        #[arg(value_enum)]
        what: Record,
    },
    /// Ask for the GoPro state.
    State,
    /// Enable or disable GoPro communication.
    Enable {
        #[arg(value_enum)]
        on: OnOff,
    },
}

pub fn button_index(b: AB) -> i32 {
    match b {
        AB::A => i32::from(Button::A.to_wire()),
        AB::B => i32::from(Button::B.to_wire()),
    }
}

/// The variant of `all` whose name is `name` (any case, `-` for `_`).
pub fn named<T: Copy>(all: &[T], name: &str, as_str: impl Fn(T) -> &'static str) -> Option<T> {
    let key = name.to_ascii_lowercase().replace('-', "_");
    all.iter().copied().find(|v| as_str(*v) == key)
}

/// The message a command sends over TCP (`None`: `listen`, `button`, `follow`).
pub fn message_for(cmd: &Cmd) -> Result<Option<SoloMessage>, String> {
    let shot = |s: &str| parse_shot(s).ok_or_else(|| format!("unknown shot `{s}`"));
    Ok(Some(match cmd {
        Cmd::Shot { shot: s } => SoloMessage::SetCurrentShot(shot(s)?),
        Cmd::Location { lat, lon, alt } => SoloMessage::Location(Location {
            lat_deg: *lat,
            lon_deg: *lon,
            alt_m: *alt,
        }),
        Cmd::Record => SoloMessage::RecordPosition,
        Cmd::Options { speed } => SoloMessage::ShotOptions {
            cruise_speed: *speed,
        },
        Cmd::CableOptions {
            interpolate,
            cw,
            speed,
        } => SoloMessage::CableCamOptions {
            cam_interpolation: u16::from(*interpolate),
            yaw_direction_cw: u16::from(*cw),
            cruise_speed: *speed,
        },
        Cmd::FollowOptions {
            speed,
            look_at,
            preference,
        } => SoloMessage::FollowOptionsV2 {
            cruise_speed: *speed,
            look_at: i32::from(*look_at),
            follow_preference: *preference as i32,
        },
        Cmd::Pause => SoloMessage::Pause,
        Cmd::GetButton { button } => SoloMessage::GetButtonSetting(ButtonSetting {
            button: button_index(*button),
            event: i32::from(ButtonEventKind::Press.to_wire()),
            shot: shots::NONE,
            mode: -1,
        }),
        Cmd::SetButton {
            button,
            shot: s,
            mode,
        } => SoloMessage::SetButtonSetting(ButtonSetting {
            button: button_index(*button),
            event: i32::from(ButtonEventKind::Press.to_wire()),
            shot: s.as_deref().map(shot).transpose()?.unwrap_or(shots::NONE),
            mode: mode.unwrap_or(-1),
        }),
        Cmd::Gopro { cmd } => match cmd {
            GoPro::Record { what } => SoloMessage::GoProRecord(match what {
                Record::Off => 0,
                Record::On => 1,
                Record::Toggle => 2,
            }),
            GoPro::State => SoloMessage::GoProRequestState,
            GoPro::Enable { on } => SoloMessage::GoProSetEnabled(u32::from(*on == OnOff::On)),
        },
        Cmd::Follow { .. } => SoloMessage::SetCurrentShot(shots::FOLLOW),
        Cmd::Button { .. } | Cmd::Listen => return Ok(None),
    }))
}

/// `start` moved `north_m` and `east_m` metres (the local tangent plane at `start`,
/// the workspace's WGS-84 geodesy).
pub fn moved(start: Location, north_m: f64, east_m: f64) -> Location {
    let frame = skymesh_geo::LocalFrame::new(skymesh_geo::Geodetic::new(
        start.lat_deg,
        start.lon_deg,
        0.0,
    ));
    let (lat_deg, lon_deg) = frame.from_ne(north_m, east_m);
    Location {
        lat_deg,
        lon_deg,
        alt_m: start.alt_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(args: &[&str]) -> Option<SoloMessage> {
        let cli = Cli::try_parse_from(std::iter::once("skymesh-solo").chain(args.iter().copied()))
            .unwrap();
        message_for(&cli.cmd).unwrap()
    }

    #[test]
    fn commands_become_messages() {
        assert_eq!(
            msg(&["shot", "orbit"]),
            Some(SoloMessage::SetCurrentShot(1))
        );
        assert_eq!(
            msg(&["location", "-35.36", "149.16", "10"]),
            Some(SoloMessage::Location(Location {
                lat_deg: -35.36,
                lon_deg: 149.16,
                alt_m: 10.0
            }))
        );
        assert_eq!(
            msg(&["options", "--speed", "-2"]),
            Some(SoloMessage::ShotOptions { cruise_speed: -2.0 })
        );
        assert_eq!(
            msg(&[
                "cable-options",
                "--interpolate",
                "true",
                "--cw",
                "false",
                "--speed",
                "3"
            ]),
            Some(SoloMessage::CableCamOptions {
                cam_interpolation: 1,
                yaw_direction_cw: 0,
                cruise_speed: 3.0
            })
        );
        assert_eq!(
            msg(&["follow-options", "--speed", "4", "--preference", "leash"]),
            Some(SoloMessage::FollowOptionsV2 {
                cruise_speed: 4.0,
                look_at: 1,
                follow_preference: 2
            })
        );
        assert_eq!(
            msg(&["set-button", "b", "--shot", "selfie"]),
            Some(SoloMessage::SetButtonSetting(ButtonSetting {
                button: 5,
                event: 0,
                shot: 0,
                mode: -1
            }))
        );
        assert_eq!(
            msg(&["gopro", "record", "toggle"]),
            Some(SoloMessage::GoProRecord(2))
        );
        assert_eq!(msg(&["listen"]), None);
        assert_eq!(
            msg(&["follow", "1", "2", "3"]),
            Some(SoloMessage::SetCurrentShot(shots::FOLLOW))
        );
    }

    #[test]
    fn positions_move_by_metres() {
        let start = Location {
            lat_deg: 60.0,
            lon_deg: 10.0,
            alt_m: 5.0,
        };
        // WGS-84 at 60°: 0.001° is 111.412 m of meridian and 55.800 m of parallel
        // (the 6,371 km sphere this used before read 111.195 m and 55.597 m).
        let north = moved(start, 111.412, 0.0);
        assert!((north.lat_deg - 60.001).abs() < 1e-6, "{north:?}");
        let east = moved(start, 0.0, 55.800);
        assert!((east.lon_deg - 10.001).abs() < 1e-6, "{east:?}");
        assert_eq!(east.alt_m, 5.0);
    }

    #[test]
    fn bad_arguments_are_refused() {
        assert!(Cli::try_parse_from(["skymesh-solo", "set-button", "a"]).is_err());
        assert!(Cli::try_parse_from([
            "skymesh-solo",
            "set-button",
            "a",
            "--shot",
            "orbit",
            "--mode",
            "3"
        ])
        .is_err());
        let cli = Cli::try_parse_from(["skymesh-solo", "shot", "warp"]).unwrap();
        assert!(message_for(&cli.cmd).is_err());
        assert!(named(Button::ALL, "camera-click", Button::as_str).is_some());
        assert!(named(ButtonEventKind::ALL, "LONG_HOLD", ButtonEventKind::as_str).is_some());
    }
}
