//! JSON for samples (cargo feature `serde`): serde and JSON-schema support for the
//! pieces of a fixed-layout sample that a plain derive does not render well.
//!
//! - [`FixedStr`] is a JSON string (at most `N` bytes of UTF-8).
//! - Enum fields stored as integers ([`crate::wire_enum!`]) are written as their
//!   stable names (`"guided"`) through [`Wire`]; a value this build does not name
//!   (another version's variant, `NO_HOLDER`) stays its integer. Both are read back.
//! - Arrays longer than serde's 32 go through [`big_array`].
//!
//! Reserved padding fields are skipped (they are always zero). None of this changes
//! a sample's layout: it only adds trait implementations.

use std::borrow::Cow;
use std::fmt;
use std::marker::PhantomData;

use schemars::{json_schema, JsonSchema, Schema, SchemaGenerator};
use serde::de::{self, Deserializer, Visitor};
use serde::ser::{SerializeSeq, Serializer};
use serde::{Deserialize, Serialize};

use crate::fixed::FixedStr;
use crate::WireEnum;

impl<const N: usize> Serialize for FixedStr<N> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl<'de, const N: usize> Deserialize<'de> for FixedStr<N> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = Cow::<'de, str>::deserialize(d)?;
        if s.len() > N {
            return Err(de::Error::custom(format_args!(
                "string of {} bytes does not fit {N}",
                s.len()
            )));
        }
        Ok(FixedStr::new(&s))
    }
}

impl<const N: usize> JsonSchema for FixedStr<N> {
    fn schema_name() -> Cow<'static, str> {
        format!("FixedStr{N}").into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "type": "string",
            "description": format!("UTF-8 text of at most {N} bytes"),
        })
    }

    fn inline_schema() -> bool {
        true
    }
}

/// Serde and schema glue for an integer field holding a [`WireEnum`] `E`:
/// `#[serde(with = "crate::json::Wire::<E>")]`. Written as the variant's name, or as
/// the integer when this build names no variant for it.
#[derive(Debug)]
pub struct Wire<E>(PhantomData<E>);

impl<E: WireEnum> Wire<E> {
    pub fn serialize<S: Serializer>(raw: &E::Repr, s: S) -> Result<S::Ok, S::Error> {
        match E::name_of(*raw) {
            Some(name) => s.serialize_str(name),
            None => s.serialize_i64((*raw).into()),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<E::Repr, D::Error> {
        struct V<E>(PhantomData<E>);
        impl<E: WireEnum> Visitor<'_> for V<E> {
            type Value = E::Repr;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "a {} name or integer", E::TYPE_NAME)
            }
            fn visit_str<Er: de::Error>(self, v: &str) -> Result<E::Repr, Er> {
                E::from_name(v).ok_or_else(|| {
                    Er::custom(format_args!(
                        "{v:?} is no {} (one of {:?})",
                        E::TYPE_NAME,
                        E::names()
                    ))
                })
            }
            fn visit_i64<Er: de::Error>(self, v: i64) -> Result<E::Repr, Er> {
                E::Repr::try_from(v)
                    .map_err(|_| Er::custom(format_args!("{v} does not fit {}", E::TYPE_NAME)))
            }
            fn visit_u64<Er: de::Error>(self, v: u64) -> Result<E::Repr, Er> {
                let v = i64::try_from(v)
                    .map_err(|_| Er::custom(format_args!("{v} does not fit {}", E::TYPE_NAME)))?;
                self.visit_i64(v)
            }
        }
        d.deserialize_any(V::<E>(PhantomData))
    }
}

impl<E: WireEnum> JsonSchema for Wire<E> {
    fn schema_name() -> Cow<'static, str> {
        E::TYPE_NAME.into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "description": format!("{}: one of the names, or the integer of a value this version does not name", E::TYPE_NAME),
            "anyOf": [
                { "type": "string", "enum": E::names() },
                { "type": "integer" }
            ]
        })
    }
}

/// The schema of an array of `N` `T`s longer than 32 (schemars has none):
/// `#[schemars(with = "crate::json::BigArray<T, N>")]` next to [`big_array`].
#[derive(Debug)]
pub struct BigArray<T, const N: usize>(PhantomData<T>);

impl<T: JsonSchema, const N: usize> JsonSchema for BigArray<T, N> {
    fn schema_name() -> Cow<'static, str> {
        format!("Array{N}_of_{}", T::schema_name()).into()
    }

    fn json_schema(generator: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "type": "array",
            "items": generator.subschema_for::<T>(),
            "minItems": N,
            "maxItems": N,
        })
    }

    fn inline_schema() -> bool {
        true
    }
}

/// `#[serde(with = "crate::json::nan_as_null")]` for an `f32` field that holds NaN
/// when unknown: JSON has no NaN, so it is written `null` (schema: number or null)
/// and `null` reads back as NaN.
pub mod nan_as_null {
    use super::*;

    pub fn serialize<S: Serializer>(v: &f32, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f32(*v)
        } else {
            s.serialize_none()
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
        Ok(Option::<f32>::deserialize(d)?.unwrap_or(f32::NAN))
    }
}

/// `#[serde(with = "crate::json::big_array")]` for arrays longer than serde's 32.
pub mod big_array {
    use super::*;

    pub fn serialize<S: Serializer, T: Serialize, const N: usize>(
        v: &[T; N],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(N))?;
        for item in v {
            seq.serialize_element(item)?;
        }
        seq.end()
    }

    pub fn deserialize<'de, D: Deserializer<'de>, T: Deserialize<'de>, const N: usize>(
        d: D,
    ) -> Result<[T; N], D::Error> {
        let items = Vec::<T>::deserialize(d)?;
        let len = items.len();
        <[T; N]>::try_from(items)
            .map_err(|_| de::Error::invalid_length(len, &format!("an array of {N}").as_str()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::FlightMode;

    #[derive(Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
    struct T {
        #[serde(with = "Wire::<FlightMode>")]
        mode: u8,
        text: FixedStr<4>,
        #[serde(with = "big_array")]
        #[schemars(with = "BigArray<u8, 40>")]
        big: [u8; 40],
    }

    #[test]
    fn enums_are_names_and_unknown_values_integers() {
        let t = T {
            mode: FlightMode::Guided.to_wire(),
            text: FixedStr::new("ab"),
            big: [7; 40],
        };
        let v = serde_json::to_value(&t).unwrap();
        assert_eq!(v["mode"], "guided");
        assert_eq!(v["text"], "ab");
        assert_eq!(v["big"].as_array().unwrap().len(), 40);
        assert_eq!(serde_json::from_value::<T>(v).unwrap(), t);

        let unknown = T { mode: 200, ..t };
        let v = serde_json::to_value(&unknown).unwrap();
        assert_eq!(v["mode"], 200);
        assert_eq!(serde_json::from_value::<T>(v).unwrap(), unknown);
    }

    #[test]
    fn bad_input_is_refused() {
        let bad_name = serde_json::json!({"mode": "flying", "text": "", "big": vec![0; 40]});
        assert!(serde_json::from_value::<T>(bad_name).is_err());
        let long = serde_json::json!({"mode": "guided", "text": "abcde", "big": vec![0; 40]});
        assert!(serde_json::from_value::<T>(long).is_err());
        let short = serde_json::json!({"mode": "guided", "text": "", "big": vec![0; 39]});
        assert!(serde_json::from_value::<T>(short).is_err());
    }

    fn round_trip<T>(sample: T)
    where
        T: Serialize + serde::de::DeserializeOwned + JsonSchema + PartialEq + fmt::Debug,
    {
        let v = serde_json::to_value(&sample).unwrap();
        assert_eq!(serde_json::from_value::<T>(v.clone()).unwrap(), sample);
        // Every field written is one the schema names, and the other way round.
        let schema = serde_json::to_value(schemars::schema_for!(T)).unwrap();
        let mut written: Vec<_> = v.as_object().unwrap().keys().cloned().collect();
        let mut named: Vec<_> = schema["properties"]
            .as_object()
            .unwrap()
            .keys()
            .cloned()
            .collect();
        written.sort();
        named.sort();
        assert_eq!(written, named, "{}", std::any::type_name::<T>());
        assert!(!written.iter().any(|k| k.starts_with("reserved")));
    }

    #[test]
    fn every_supported_sample_round_trips_and_matches_its_schema() {
        use crate::*;
        let mut status = VehicleStatus {
            mode: FlightMode::Guided.to_wire(),
            gps_fix: GpsFix::Fix3d.to_wire(),
            status_text: FixedStr::new("PreArm: ok"),
            ..Default::default()
        };
        status.header.service = ServiceId::AutopilotLink.to_wire();
        let v = serde_json::to_value(status).unwrap();
        assert_eq!(v["mode"], "guided");
        assert_eq!(v["gps_fix"], "3d");
        assert_eq!(v["status_text"], "PreArm: ok");
        assert_eq!(v["header"]["service"], "autopilot-link");
        round_trip(status);
        round_trip(VehicleState {
            alt_rel_m: 12.5,
            ..Default::default()
        });
        let unknown = VehicleState {
            alt_ellipsoid_m: f32::NAN,
            ..Default::default()
        };
        let v = serde_json::to_value(unknown).unwrap();
        assert!(v["alt_ellipsoid_m"].is_null());
        let back: VehicleState = serde_json::from_value(v).unwrap();
        assert!(back.alt_ellipsoid_m.is_nan());
        round_trip(VehicleCommand::default());
        round_trip(CommandAck::default());
        round_trip(AuthorityState::default());
        round_trip(ArbiterEvent::default());
        round_trip(GeofenceSet::default());
        round_trip(PayloadState::default());
        round_trip(VisionState::default());
        round_trip(SwarmState::default());
    }

    #[test]
    fn schema_lists_the_names() {
        let schema = serde_json::to_value(schemars::schema_for!(T)).unwrap();
        let text = schema.to_string();
        assert!(text.contains("\"guided\""), "{text}");
        assert_eq!(schema["properties"]["text"]["type"], "string");
    }
}
