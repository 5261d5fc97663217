//! The `skymesh-gc` command line: parsing and the records each command sends
//! (pure, tested here; the binary only does the I/O).

use std::net::SocketAddr;

use clap::{Parser, Subcommand};
use gc_proto::{pack_text, NetCmdType, Params, PoseRecord, Record};

/// Drive a swarm through skymesh's GroundControl state server and watch its pose
/// broadcast. DRONES is an id, a list or ranges: `3`, `0,2`, `0-4,7`.
#[derive(Debug, Parser)]
#[command(name = "skymesh-gc", version)]
pub struct Cli {
    /// The state server (groundcontrol-gateway's `listen`).
    #[arg(long, default_value = "127.0.0.1:8000")]
    pub server: SocketAddr,
    /// Seconds to print replies after sending.
    #[arg(long, default_value_t = 2.0)]
    pub wait: f64,
    #[command(subcommand)]
    pub cmd: Cmd,
}

#[derive(Debug, Clone, PartialEq, Subcommand)]
pub enum Cmd {
    /// PING_REQUEST; prints the round trip.
    Ping,
    /// CMD_EXT_GO_EXTERNAL: take off.
    Takeoff { drones: String },
    /// CMD_EXT_GO_HOME: land at home.
    Land { drones: String },
    /// CMD_EXT_WAYPOINT: queue a waypoint (site metres: x east, y north, z up).
    #[command(allow_negative_numbers = true)]
    Waypoint {
        drones: String,
        x: f32,
        y: f32,
        z: f32,
        /// m/s (0: the queue's default).
        #[arg(long, default_value_t = 0.0)]
        speed: f32,
        /// CCW degrees from east.
        #[arg(long, default_value_t = 0.0)]
        yaw: f32,
    },
    /// CMD_EXT_WAYPOINT_FOLLOW: replace the follow target (runs until halt).
    #[command(allow_negative_numbers = true)]
    Follow {
        drones: String,
        x: f32,
        y: f32,
        z: f32,
        #[arg(long, default_value_t = 0.0)]
        speed: f32,
        #[arg(long, default_value_t = 0.0)]
        yaw: f32,
    },
    /// CMD_EXT_HALT: clear the current command and the queue.
    Halt { drones: String },
    /// CMD_EXT_CHECK_ALL_IDLE: one answer per drone.
    Idle,
    /// EXT_PARAM_1 (rgb) + CMD_EXT_COLOR (fade seconds).
    Color {
        drones: String,
        r: f32,
        g: f32,
        b: f32,
        #[arg(default_value_t = 0.0)]
        secs: f32,
    },
    /// CMD_EXT_PLAYBACK_ANIM: play animation frames FIRST..=LAST (-1: to the end).
    #[command(allow_negative_numbers = true)]
    Anim {
        drones: String,
        first: i32,
        last: i32,
        #[arg(long = "loop")]
        looped: bool,
        #[arg(long, default_value_t = 1.0)]
        speed: f32,
    },
    /// CMD_EXT_TEXT: up to 20 bytes for the drone's display.
    Text { drones: String, text: String },
    /// CMD_EMERGENCY_MODE (privileged clients only).
    Emergency { drones: String },
    /// Print the pose broadcast.
    ListenPoses {
        #[arg(long, default_value_t = 6666)]
        port: u16,
        /// Stop after this many datagrams (default: until Ctrl-C).
        #[arg(long)]
        count: Option<u64>,
    },
}

/// `3`, `0,2`, `0-4,7` → the ids.
pub fn parse_drones(s: &str) -> Result<Vec<i32>, String> {
    let mut out = Vec::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let id = |t: &str| {
            t.trim()
                .parse::<u16>()
                .ok()
                .filter(|&v| v != u16::MAX)
                .map(i32::from)
                .ok_or_else(|| format!("`{t}` is not a drone id (0..65534)"))
        };
        match part.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (id(a)?, id(b)?);
                if a > b {
                    return Err(format!("range `{part}` is empty"));
                }
                if b - a >= 1024 {
                    return Err(format!("range `{part}` is longer than 1024 drones"));
                }
                out.extend(a..=b);
            }
            None => out.push(id(part)?),
        }
    }
    if out.is_empty() {
        return Err("no drone given".to_string());
    }
    Ok(out)
}

fn yaw_cdeg(yaw_deg: f32) -> Result<i32, String> {
    let v = (yaw_deg * 100.0).round();
    if v.is_finite() && (-36_000.0..=36_000.0).contains(&v) {
        Ok(v as i32)
    } else {
        Err(format!("--yaw {yaw_deg} is outside -360..=360 degrees"))
    }
}

/// The records a command sends (`Ping` and `ListenPoses` send none here).
pub fn records_for(cmd: &Cmd) -> Result<Vec<Record>, String> {
    let per_drone = |drones: &str, make: &dyn Fn(i32) -> Vec<Record>| {
        parse_drones(drones).map(|ids| ids.into_iter().flat_map(make).collect::<Vec<_>>())
    };
    let simple = |t: NetCmdType| move |d: i32| vec![Record::new(t, d)];
    Ok(match cmd {
        Cmd::Ping | Cmd::ListenPoses { .. } => Vec::new(),
        Cmd::Takeoff { drones } => per_drone(drones, &simple(NetCmdType::CmdExtGoExternal))?,
        Cmd::Land { drones } => per_drone(drones, &simple(NetCmdType::CmdExtGoHome))?,
        Cmd::Halt { drones } => per_drone(drones, &simple(NetCmdType::CmdExtHalt))?,
        Cmd::Idle => vec![Record::new(NetCmdType::CmdExtCheckAllIdle, 0)],
        Cmd::Waypoint {
            drones,
            x,
            y,
            z,
            speed,
            yaw,
        }
        | Cmd::Follow {
            drones,
            x,
            y,
            z,
            speed,
            yaw,
        } => {
            let t = if matches!(cmd, Cmd::Waypoint { .. }) {
                NetCmdType::CmdExtWaypoint
            } else {
                NetCmdType::CmdExtWaypointFollow
            };
            let yaw = yaw_cdeg(*yaw)?;
            per_drone(drones, &|d| {
                vec![Record::floats(t, d, yaw, 0, [*x, *y, *z, *speed])]
            })?
        }
        Cmd::Color {
            drones,
            r,
            g,
            b,
            secs,
        } => per_drone(drones, &|d| {
            vec![
                Record::floats(NetCmdType::ExtParam1, d, 0, 0, [*r, *g, *b, 0.0]),
                Record::floats(NetCmdType::CmdExtColor, d, 0, 0, [*secs, 0.0, 0.0, 0.0]),
            ]
        })?,
        Cmd::Anim {
            drones,
            first,
            last,
            looped,
            speed,
        } => {
            let l = if *looped { 1.0 } else { 0.0 };
            per_drone(drones, &|d| {
                vec![Record::floats(
                    NetCmdType::CmdExtPlaybackAnim,
                    d,
                    *first,
                    *last,
                    [l, *speed, 1.0, 1.0],
                )]
            })?
        }
        Cmd::Text { drones, text } => {
            let (int2, longs) = pack_text(text).map_err(|e| e.to_string())?;
            per_drone(drones, &|d| {
                vec![Record {
                    int2,
                    params: Params::Longs(longs),
                    ..Record::new(NetCmdType::CmdExtText, d)
                }]
            })?
        }
        Cmd::Emergency { drones } => per_drone(drones, &|d| {
            vec![Record {
                int1: 1,
                ..Record::new(NetCmdType::CmdEmergencyMode, d)
            }]
        })?,
    })
}

/// One line for a record from the server.
pub fn describe(r: &Record) -> String {
    let name_of = |kind: i32| {
        NetCmdType::from_i32(kind)
            .map_or_else(|| format!("type {kind:#x}"), |t| t.name().to_string())
    };
    match r.net_type() {
        Some(NetCmdType::AckCmdSuccess) => {
            format!("drone {}: {} succeeded", r.context, name_of(r.int1))
        }
        Some(NetCmdType::AckCmdTimeout) => {
            format!("drone {}: {} timed out", r.context, name_of(r.int1))
        }
        Some(NetCmdType::CmdExtCheckAllIdle) => format!(
            "drone {}: {}",
            r.context,
            if r.int1 != 0 { "idle" } else { "busy" }
        ),
        Some(NetCmdType::PingResponse) => format!("PING_RESPONSE seq {}", r.int1),
        _ => r.to_string(),
    }
}

/// One line for a pose record.
pub fn describe_pose(p: &PoseRecord) -> String {
    format!(
        "drone {:>3} state {:>2} flags {:#04x} pos ({:7.2}, {:7.2}, {:6.2}) yaw {:6.1} target ({:7.2}, {:7.2}, {:6.2}) rgb ({:.2}, {:.2}, {:.2}) t {:.2} frame {}",
        p.id,
        p.drone_state,
        p.flags,
        p.tracking[0],
        p.tracking[1],
        p.tracking[2],
        p.tracking_yaw_deg,
        p.target[0],
        p.target[1],
        p.target[2],
        p.color[0],
        p.color[1],
        p.color[2],
        p.timestamp,
        p.frame_count
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use gc_proto::unpack_text;

    fn parse(args: &[&str]) -> Cli {
        Cli::try_parse_from(std::iter::once("skymesh-gc").chain(args.iter().copied())).unwrap()
    }

    #[test]
    fn drone_lists() {
        assert_eq!(parse_drones("3").unwrap(), [3]);
        assert_eq!(parse_drones("0-2,7").unwrap(), [0, 1, 2, 7]);
        assert!(parse_drones("").is_err());
        assert!(parse_drones("2-1").is_err());
        assert!(parse_drones("65535").is_err());
        assert!(parse_drones("x").is_err());
    }

    #[test]
    fn waypoint_with_negative_coordinates() {
        let cli = parse(&[
            "waypoint", "1,2", "-5", "3.5", "10", "--speed", "2", "--yaw", "-90",
        ]);
        let recs = records_for(&cli.cmd).unwrap();
        assert_eq!(recs.len(), 2);
        assert_eq!(recs[1].context, 2);
        assert_eq!(recs[1].int1, -9000);
        assert_eq!(recs[1].float_params(), [-5.0, 3.5, 10.0, 2.0]);
        assert_eq!(recs[0].net_type(), Some(NetCmdType::CmdExtWaypoint));
    }

    #[test]
    fn colour_text_anim_idle() {
        let recs = records_for(&parse(&["color", "4", "1", "0", "0.5", "2"]).cmd).unwrap();
        assert_eq!(recs[0].net_type(), Some(NetCmdType::ExtParam1));
        assert_eq!(recs[0].float_params(), [1.0, 0.0, 0.5, 0.0]);
        assert_eq!(recs[1].float_params()[0], 2.0);
        let recs = records_for(&parse(&["text", "0", "HELLO"]).cmd).unwrap();
        assert_eq!(
            unpack_text(recs[0].int2, recs[0].params.as_longs()).unwrap(),
            "HELLO"
        );
        assert!(records_for(&parse(&["text", "0", "this is far too long!!"]).cmd).is_err());
        let recs = records_for(&parse(&["anim", "0", "10", "-1", "--loop"]).cmd).unwrap();
        assert_eq!((recs[0].int1, recs[0].int2), (10, -1));
        assert_eq!(recs[0].float_params()[..2], [1.0, 1.0]);
        let recs = records_for(&parse(&["idle"]).cmd).unwrap();
        assert_eq!(recs[0].net_type(), Some(NetCmdType::CmdExtCheckAllIdle));
        assert!(
            records_for(&parse(&["waypoint", "0", "0", "0", "0", "--yaw", "400"]).cmd).is_err()
        );
    }

    #[test]
    fn descriptions() {
        assert_eq!(
            describe(&Record::ack(true, 3, 0xA6)),
            "drone 3: CMD_EXT_WAYPOINT succeeded"
        );
        assert_eq!(describe(&Record::idle_state(2, false)), "drone 2: busy");
    }
}
