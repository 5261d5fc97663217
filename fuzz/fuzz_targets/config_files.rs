//! Arbitrary text through every service's TOML config parser, the service picked by
//! the first byte (`data[0] % 14`, see `SERVICES`; the seeds are each shipped
//! `deploy/*.toml` behind its selector byte, the dictionary holds every key).
//!
//! Checks, beyond "never panics" (and never hangs or eats memory: a path value such as
//! a CA bundle or a Y4M file may name /dev/zero or /dev/stdin):
//! - parsing is a pure function of the text: the same text parsed twice gives the
//!   same settings or the same error;
//! - a refusal names what it refuses (a non-empty field, origin or message);
//! - accepted settings hold the ranges the parser promises (a few re-checked here).
#![no_main]

use std::fmt::Debug;
use std::path::Path;

use libfuzzer_sys::fuzz_target;
use skymesh_runtime::config::{parse, ConfigError, ServiceConfig};

/// The selector byte's meaning (`data[0] % SERVICES.len()`), and the deploy file each
/// seed comes from. Keep in step with `fuzz/seed-config-corpus.sh`.
pub const SERVICES: [&str; 14] = [
    "autopilot-link",
    "camera",
    "digiview-gateway",
    "dji-gateway",
    "groundcontrol-gateway",
    "hardware",
    "imc-gateway",
    "mqtt-broker",
    "shot-engine",
    "solo-gateway",
    "skymesh", // the supervisor's deploy/skymesh.toml
    "swarm-queue",
    "vehicle-sim",
    "vision-pipeline",
];

/// A refusal must say what it refuses.
fn check_error(e: &ConfigError) {
    match e {
        ConfigError::Invalid { field, message } => {
            assert!(!field.is_empty(), "a refusal without a field: {message}");
            assert!(
                !message.is_empty(),
                "field `{field}` refused without a reason"
            );
        }
        ConfigError::Parse { origin, message } | ConfigError::Ipc { origin, message } => {
            assert!(!origin.is_empty() && !message.is_empty(), "{e}");
        }
        ConfigError::Env { message, .. } => assert!(!message.is_empty()),
        ConfigError::Read { .. } | ConfigError::File(_) => {}
    }
    assert!(!e.to_string().is_empty());
}

/// Parses `text` twice as service `C`; the outcome must not change. The settings are
/// returned for the service's own range checks.
fn twice<C>(text: &str) -> Option<C::Settings>
where
    C: ServiceConfig,
    C::Settings: PartialEq + Debug,
{
    let first = parse::<C>(text, "fuzz");
    let second = parse::<C>(text, "fuzz");
    match (first, second) {
        (Ok(a), Ok(b)) => {
            assert_eq!(a, b, "the same text parsed to different settings");
            Some(a)
        }
        (Err(a), Err(b)) => {
            assert_eq!(a.to_string(), b.to_string(), "the same text, two errors");
            check_error(&a);
            None
        }
        (a, b) => panic!("the same text parsed once as {a:?} and once as {b:?}"),
    }
}

fn in_range<T: PartialOrd + Debug>(field: &str, v: T, min: T, max: T) {
    assert!(
        v >= min && v <= max,
        "accepted {field} = {v:?} outside {min:?}..={max:?}"
    );
}

fuzz_target!(|data: &[u8]| {
    let Some((&selector, rest)) = data.split_first() else {
        return;
    };
    let text = String::from_utf8_lossy(rest);
    let text = text.as_ref();
    match usize::from(selector) % SERVICES.len() {
        0 => {
            if let Some(s) = twice::<skymesh_autopilot_link::RawConfig>(text) {
                in_range("command_retries", s.command_retries, 0, 5);
                assert!(s.reconnect_min <= s.reconnect_max, "{s:?}");
            }
        }
        1 => {
            if let Some(s) = twice::<skymesh_camera::RawConfig>(text) {
                in_range("width", s.width, 16, 1920);
                in_range("height", s.height, 16, 1080);
                in_range("fps", s.fps, 1, 60);
                if let skymesh_camera::Source::Y4m(y) = &s.source {
                    assert!(y.path.is_file(), "accepted Y4M {:?} is not a file", y.path);
                }
            }
        }
        2 => {
            if let Some(s) = twice::<skymesh_digiview_gateway::RawConfig>(text) {
                in_range("max_clients", s.max_clients, 1, 1024);
                in_range("outgoing_queue", s.outgoing_queue, 16, 65_536);
                in_range("max_frames_per_s", s.max_frames_per_s, 1, 100_000);
            }
        }
        3 => {
            if let Some(s) = twice::<skymesh_dji_gateway::RawConfig>(text) {
                // CA bundles are accepted only after they were read: regular files.
                for ca in [&s.broker.tls_ca_file, &s.drc.ca_file]
                    .into_iter()
                    .flatten()
                {
                    assert!(ca.is_file(), "accepted CA bundle {ca:?} is not a file");
                }
            }
        }
        4 => {
            if let Some(s) = twice::<skymesh_groundcontrol_gateway::RawConfig>(text) {
                in_range("max_clients", s.max_clients, 1, 4096);
                in_range("outgoing_queue", s.outgoing_queue, 16, 65_536);
            }
        }
        5 => {
            twice::<skymesh_hardware::RawConfig>(text);
        }
        6 => {
            twice::<skymesh_imc_gateway::RawConfig>(text);
        }
        7 => {
            if let Some(s) = twice::<skymesh_mqtt_broker::RawConfig>(text) {
                in_range("max_connections", s.max_connections, 1, 10_000);
            }
        }
        8 => {
            twice::<skymesh_shot_engine::RawConfig>(text);
        }
        9 => {
            if let Some(s) = twice::<skymesh_solo_gateway::RawConfig>(text) {
                in_range("outgoing_queue", s.outgoing_queue, 4, 65_536);
            }
        }
        10 => {
            // The supervisor: parse only (finding the binaries is `locate_files`, later).
            let base = Path::new("/nonexistent/skymesh-fuzz");
            let parse = || skymesh_supervisor::config::Settings::parse(text, "fuzz", base);
            match (parse(), parse()) {
                (Ok(a), Ok(b)) => assert_eq!(format!("{a:?}"), format!("{b:?}")),
                (Err(a), Err(b)) => {
                    assert_eq!(a.to_string(), b.to_string());
                    check_error(&a);
                }
                (a, b) => panic!("the same text parsed once as {a:?} and once as {b:?}"),
            }
        }
        11 => {
            if let Some(s) = twice::<skymesh_swarm_queue::RawConfig>(text) {
                in_range("lcd_width", s.lcd_width, 1, 40);
                in_range("queue_capacity", s.queue_capacity, 1, 65_535);
            }
        }
        12 => {
            // vehicle-sim's Settings are not PartialEq: compare their Debug text.
            let parse = || parse::<skymesh_vehicle_sim::RawConfig>(text, "fuzz");
            match (parse(), parse()) {
                (Ok(a), Ok(b)) => assert_eq!(format!("{a:?}"), format!("{b:?}")),
                (Err(a), Err(b)) => {
                    assert_eq!(a.to_string(), b.to_string());
                    check_error(&a);
                }
                (a, b) => panic!("the same text parsed once as {a:?} and once as {b:?}"),
            }
        }
        _ => {
            if let Some(s) = twice::<skymesh_vision_pipeline::RawConfig>(text) {
                for st in &s.streams {
                    in_range("stream.width", st.width, 640, 1920);
                    in_range("stream.height", st.height, 480, 1080);
                }
            }
        }
    }
});
