//! Samples as JSON (MCAP message encoding `json`) and their JSON schemas (schema
//! encoding `jsonschema`), through the ipc-types `serde` feature.

use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde::Serialize;
use skymesh_ipc_types::Sample;

/// MCAP message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "json";
/// MCAP schema encoding of every schema.
pub const SCHEMA_ENCODING: &str = "jsonschema";

/// A sample type that can be recorded and replayed.
pub trait Recordable: Sample + Serialize + DeserializeOwned + JsonSchema {}
impl<T: Sample + Serialize + DeserializeOwned + JsonSchema> Recordable for T {}

/// Runs `$body` with `$T` the sample type of `$kind` (a [`super::topics::Kind`]).
macro_rules! with_kind {
    ($kind:expr, $T:ident => $body:expr) => {{
        use $crate::topics::Kind;
        match $kind {
            Kind::VehicleState => {
                type $T = skymesh_ipc_types::VehicleState;
                $body
            }
            Kind::VehicleStatus => {
                type $T = skymesh_ipc_types::VehicleStatus;
                $body
            }
            Kind::VehicleCommand => {
                type $T = skymesh_ipc_types::VehicleCommand;
                $body
            }
            Kind::CommandAck => {
                type $T = skymesh_ipc_types::CommandAck;
                $body
            }
            Kind::AuthorityState => {
                type $T = skymesh_ipc_types::AuthorityState;
                $body
            }
            Kind::ArbiterEvent => {
                type $T = skymesh_ipc_types::ArbiterEvent;
                $body
            }
            Kind::GeofenceSet => {
                type $T = skymesh_ipc_types::GeofenceSet;
                $body
            }
            Kind::PayloadState => {
                type $T = skymesh_ipc_types::PayloadState;
                $body
            }
            Kind::VisionState => {
                type $T = skymesh_ipc_types::VisionState;
                $body
            }
            Kind::SwarmState => {
                type $T = skymesh_ipc_types::SwarmState;
                $body
            }
        }
    }};
}
pub(crate) use with_kind;

use super::topics::Kind;

/// The JSON schema of `kind`'s samples (draft 2020-12, titled with the type name).
pub fn schema(kind: Kind) -> Vec<u8> {
    fn of<T: Recordable>(name: &str) -> Vec<u8> {
        let mut schema = schemars::schema_for!(T);
        schema.insert("title".into(), name.into());
        serde_json::to_vec(&schema).unwrap_or_default()
    }
    with_kind!(kind, T => of::<T>(kind.schema_name()))
}

/// Fields holding a `CLOCK_MONOTONIC` time of the recording machine (besides
/// `header.stamp_ns`): replay moves them by as much as it moves the sample, so a
/// consumer computing an age from them sees the age they had when recorded.
pub fn is_monotonic_stamp(field: &str) -> bool {
    field.ends_with("_stamp_ns") || field.ends_with("_since_ns") || field.ends_with("_mono_ns")
}

/// Adds `delta` ns to every non-zero monotonic stamp field (see
/// [`is_monotonic_stamp`]) of `value`, at any depth.
pub fn shift_stamps(value: &mut serde_json::Value, delta: i128) {
    match value {
        serde_json::Value::Object(map) => {
            for (key, v) in map.iter_mut() {
                if is_monotonic_stamp(key) {
                    if let Some(ns) = v.as_u64().filter(|&ns| ns != 0) {
                        let moved = (i128::from(ns) + delta).clamp(1, i128::from(u64::MAX));
                        *v = serde_json::Value::from(moved as u64);
                    }
                } else {
                    shift_stamps(v, delta);
                }
            }
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(|v| shift_stamps(v, delta)),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::topics::FAMILIES;
    use skymesh_ipc_types::{FlightMode, VehicleStatus};

    #[test]
    fn every_kind_has_a_titled_object_schema() {
        for f in &FAMILIES {
            let schema: serde_json::Value = serde_json::from_slice(&schema(f.kind)).unwrap();
            assert_eq!(schema["title"], f.schema_name);
            assert_eq!(schema["type"], "object");
            assert!(
                schema["properties"]["header"].is_object(),
                "{}",
                f.schema_name
            );
        }
    }

    #[test]
    fn enums_are_names_in_the_schema_and_the_sample() {
        let schema: serde_json::Value =
            serde_json::from_slice(&schema(Kind::VehicleStatus)).unwrap();
        let text = schema.to_string();
        assert!(text.contains("\"alt_hold\""), "{text}");
        let status = VehicleStatus {
            mode: FlightMode::AltHold.to_wire(),
            ..Default::default()
        };
        let v = serde_json::to_value(status).unwrap();
        assert_eq!(v["mode"], "alt_hold");
    }

    #[test]
    fn stamps_move_but_zero_and_other_fields_stay() {
        let mut v = serde_json::json!({
            "header": {"stamp_ns": 100, "seq": 5},
            "position_stamp_ns": 90,
            "flight_since_ns": 0,
            "streams": [{"last_capture_mono_ns": 80}],
            "time_boot_ms": 7
        });
        shift_stamps(&mut v, 1000);
        assert_eq!(v["position_stamp_ns"], 1090);
        assert_eq!(v["flight_since_ns"], 0);
        assert_eq!(v["streams"][0]["last_capture_mono_ns"], 1080);
        assert_eq!(v["time_boot_ms"], 7);
        assert_eq!(v["header"]["seq"], 5);
        shift_stamps(&mut v, -5000);
        assert_eq!(v["position_stamp_ns"], 1);
    }
}
