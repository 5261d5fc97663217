//! Field checks against the document's constraint column. Each check returns the
//! value or a [`Reject`] naming the field path (`data.points[0].latitude`), the code
//! of [`crate::codes`] and a short reason.
//!
//! Conventions (docs/protocols.md, "DJI request checks"):
//! - a JSON `null` counts as absent (a required field that is null is missing);
//! - fields the method does not define are ignored (forward compatibility: a newer
//!   cloud may send more);
//! - `int` fields take integer JSON numbers only (`1.5` and `1.0` are the wrong type;
//!   an integer beyond i64 is out of range); `double`/`float` fields take any JSON
//!   number, checked finite (JSON cannot carry NaN/inf, but the check costs nothing).

use std::ops::RangeInclusive;

use serde_json::{Map, Value};

use crate::codes::{
    BAD_ARRAY_SIZE, BAD_TEXT, MAX_TEXT_LEN, MISSING_FIELD, NOT_IN_ENUM, OUT_OF_RANGE,
    UNKNOWN_METHOD, WRONG_TYPE,
};
use crate::Reject;

pub(crate) fn reject(code: u32, field: impl Into<String>, reason: impl Into<String>) -> Reject {
    Reject {
        code,
        field: field.into(),
        reason: reason.into(),
    }
}

/// `text` shortened to at most `max` bytes on a character boundary (for logs).
pub(crate) fn clip(text: &str, max: usize) -> &str {
    if text.len() <= max {
        return text;
    }
    let mut end = max;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

/// The method is not one of this topic's: the field is the (clipped) method name.
pub(crate) fn unknown_method(method: &str) -> Reject {
    reject(
        UNKNOWN_METHOD,
        clip(method, MAX_TEXT_LEN),
        "unknown method on this topic",
    )
}

fn json_type(value: &Value) -> &'static str {
    match value {
        Value::Null => "null",
        Value::Bool(_) => "bool",
        Value::Number(n) if n.is_f64() => "non-integer number",
        Value::Number(_) => "integer",
        Value::String(_) => "string",
        Value::Array(_) => "array",
        Value::Object(_) => "object",
    }
}

fn wrong_type(path: &str, expected: &str, value: &Value) -> Reject {
    reject(
        WRONG_TYPE,
        path,
        format!("expected {expected}, got {}", json_type(value)),
    )
}

/// Methods without data: `data` absent/null or any object (`{}` in the document's
/// examples; unknown fields ignored).
pub(crate) fn no_data(data: &Value) -> Result<(), Reject> {
    match data {
        Value::Null | Value::Object(_) => Ok(()),
        other => Err(wrong_type("data", "object or null", other)),
    }
}

/// An integer JSON number within `range`.
pub(crate) fn int_value(
    value: &Value,
    path: &str,
    range: RangeInclusive<i64>,
) -> Result<i64, Reject> {
    let Value::Number(n) = value else {
        return Err(wrong_type(path, "integer", value));
    };
    let Some(v) = n.as_i64() else {
        return Err(if n.is_u64() {
            reject(OUT_OF_RANGE, path, format!("above max {}", range.end()))
        } else {
            wrong_type(path, "integer", value)
        });
    };
    if v < *range.start() {
        return Err(reject(
            OUT_OF_RANGE,
            path,
            format!("below min {}", range.start()),
        ));
    }
    if v > *range.end() {
        return Err(reject(
            OUT_OF_RANGE,
            path,
            format!("above max {}", range.end()),
        ));
    }
    Ok(v)
}

/// Any JSON number, finite, within `min..=max`.
pub(crate) fn num_value(value: &Value, path: &str, min: f64, max: f64) -> Result<f64, Reject> {
    let Some(v) = value.as_f64() else {
        return Err(wrong_type(path, "number", value));
    };
    if !v.is_finite() {
        return Err(reject(OUT_OF_RANGE, path, "not finite"));
    }
    if v < min {
        return Err(reject(OUT_OF_RANGE, path, format!("below min {min}")));
    }
    if v > max {
        return Err(reject(OUT_OF_RANGE, path, format!("above max {max}")));
    }
    Ok(v)
}

/// A JSON string of 1..=`max_len` bytes (0..= when `allow_empty`).
pub(crate) fn text_value(
    value: &Value,
    path: &str,
    allow_empty: bool,
    max_len: usize,
) -> Result<String, Reject> {
    let Value::String(s) = value else {
        return Err(wrong_type(path, "string", value));
    };
    if s.is_empty() && !allow_empty {
        return Err(reject(BAD_TEXT, path, "empty"));
    }
    if s.len() > max_len {
        return Err(reject(
            BAD_TEXT,
            path,
            format!("longer than {max_len} bytes"),
        ));
    }
    Ok(s.clone())
}

/// A JSON string equal to one of `table`'s names.
pub(crate) fn enum_str_value<T: Copy>(
    value: &Value,
    path: &str,
    table: &[(&str, T)],
) -> Result<T, Reject> {
    let Value::String(s) = value else {
        return Err(wrong_type(path, "string", value));
    };
    table
        .iter()
        .find(|(name, _)| name == s)
        .map(|&(_, v)| v)
        .ok_or_else(|| {
            let names: Vec<&str> = table.iter().map(|(name, _)| *name).collect();
            reject(
                NOT_IN_ENUM,
                path,
                format!("`{}` is not one of {}", clip(s, 32), names.join("|")),
            )
        })
}

/// An integer JSON number equal to one of `table`'s codes.
pub(crate) fn enum_int_value<T: Copy>(
    value: &Value,
    path: &str,
    table: &[(i64, T)],
) -> Result<T, Reject> {
    let Value::Number(n) = value else {
        return Err(wrong_type(path, "integer", value));
    };
    if !(n.is_i64() || n.is_u64()) {
        return Err(wrong_type(path, "integer", value));
    }
    n.as_i64()
        .and_then(|v| table.iter().find(|(code, _)| *code == v))
        .map(|&(_, v)| v)
        .ok_or_else(|| {
            let codes: Vec<String> = table.iter().map(|(code, _)| code.to_string()).collect();
            reject(
                NOT_IN_ENUM,
                path,
                format!("{n} is not one of {}", codes.join("|")),
            )
        })
}

/// A JSON object under check, with the path its fields are reported under.
#[derive(Debug)]
pub(crate) struct Obj<'a> {
    map: &'a Map<String, Value>,
    path: String,
}

impl<'a> Obj<'a> {
    /// `value` must be an object; null/absent is a missing `path`.
    pub(crate) fn of(value: &'a Value, path: String) -> Result<Self, Reject> {
        match value {
            Value::Object(map) => Ok(Obj { map, path }),
            Value::Null => Err(reject(MISSING_FIELD, path, "required")),
            other => Err(wrong_type(&path, "object", other)),
        }
    }

    /// The envelope's `data`.
    pub(crate) fn data(value: &'a Value) -> Result<Self, Reject> {
        Obj::of(value, "data".to_owned())
    }

    pub(crate) fn path_of(&self, key: &str) -> String {
        format!("{}.{key}", self.path)
    }

    /// The value of `key` and its path; `None` when absent or null.
    pub(crate) fn opt(&self, key: &str) -> Option<(&'a Value, String)> {
        match self.map.get(key) {
            None | Some(Value::Null) => None,
            Some(v) => Some((v, self.path_of(key))),
        }
    }

    /// The value of `key` and its path; absent or null is [`MISSING_FIELD`].
    pub(crate) fn req(&self, key: &str) -> Result<(&'a Value, String), Reject> {
        self.opt(key)
            .ok_or_else(|| reject(MISSING_FIELD, self.path_of(key), "required"))
    }

    pub(crate) fn int(&self, key: &str, range: RangeInclusive<i64>) -> Result<i64, Reject> {
        let (v, path) = self.req(key)?;
        int_value(v, &path, range)
    }

    /// An integer in a `u8` range.
    pub(crate) fn int_u8(&self, key: &str, range: RangeInclusive<u8>) -> Result<u8, Reject> {
        let wide = i64::from(*range.start())..=i64::from(*range.end());
        let v = self.int(key, wide)?;
        u8::try_from(v).map_err(|_| reject(OUT_OF_RANGE, self.path_of(key), "not a u8"))
    }

    pub(crate) fn num(&self, key: &str, min: f64, max: f64) -> Result<f64, Reject> {
        let (v, path) = self.req(key)?;
        num_value(v, &path, min, max)
    }

    pub(crate) fn opt_num(&self, key: &str, min: f64, max: f64) -> Result<Option<f64>, Reject> {
        self.opt(key)
            .map(|(v, path)| num_value(v, &path, min, max))
            .transpose()
    }

    /// Any finite number (the document gives no range).
    pub(crate) fn finite(&self, key: &str) -> Result<f64, Reject> {
        self.num(key, f64::MIN, f64::MAX)
    }

    pub(crate) fn boolean(&self, key: &str) -> Result<bool, Reject> {
        let (v, path) = self.req(key)?;
        v.as_bool().ok_or_else(|| wrong_type(&path, "bool", v))
    }

    /// Non-empty text of at most [`MAX_TEXT_LEN`] bytes.
    pub(crate) fn text(&self, key: &str) -> Result<String, Reject> {
        let (v, path) = self.req(key)?;
        text_value(v, &path, false, MAX_TEXT_LEN)
    }

    pub(crate) fn enum_str<T: Copy>(&self, key: &str, table: &[(&str, T)]) -> Result<T, Reject> {
        let (v, path) = self.req(key)?;
        enum_str_value(v, &path, table)
    }

    pub(crate) fn enum_int<T: Copy>(&self, key: &str, table: &[(i64, T)]) -> Result<T, Reject> {
        let (v, path) = self.req(key)?;
        enum_int_value(v, &path, table)
    }

    pub(crate) fn opt_enum_int<T: Copy>(
        &self,
        key: &str,
        table: &[(i64, T)],
    ) -> Result<Option<T>, Reject> {
        self.opt(key)
            .map(|(v, path)| enum_int_value(v, &path, table))
            .transpose()
    }

    pub(crate) fn object(&self, key: &str) -> Result<Obj<'a>, Reject> {
        let (v, path) = self.req(key)?;
        Obj::of(v, path)
    }

    pub(crate) fn opt_object(&self, key: &str) -> Result<Option<Obj<'a>>, Reject> {
        self.opt(key).map(|(v, path)| Obj::of(v, path)).transpose()
    }

    /// A JSON array with `size` items.
    pub(crate) fn array(
        &self,
        key: &str,
        size: RangeInclusive<usize>,
    ) -> Result<(&'a [Value], String), Reject> {
        let (v, path) = self.req(key)?;
        let Value::Array(items) = v else {
            return Err(wrong_type(&path, "array", v));
        };
        if !size.contains(&items.len()) {
            let want = if size.start() == size.end() {
                format!("exactly {}", size.start())
            } else {
                format!("{}..={}", size.start(), size.end())
            };
            return Err(reject(
                BAD_ARRAY_SIZE,
                path,
                format!("{} items, expected {want}", items.len()),
            ));
        }
        Ok((items, path))
    }
}

/// `{type}-{subtype}-{gimbalindex}`: three decimal integers (each fits u32).
pub(crate) fn is_payload_index(s: &str) -> bool {
    let parts: Vec<&str> = s.split('-').collect();
    parts.len() == 3
        && parts.iter().all(|p| {
            !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()) && p.parse::<u32>().is_ok()
        })
}

/// `host:port`: a host without spaces, slashes or control characters (an IPv6 host in
/// brackets), and a decimal port 1..=65535.
pub(crate) fn is_host_port(s: &str) -> bool {
    let Some((host, port)) = s.rsplit_once(':') else {
        return false;
    };
    let port_ok = !port.is_empty()
        && port.len() <= 5
        && port.bytes().all(|b| b.is_ascii_digit())
        && port.parse::<u32>().is_ok_and(|p| (1..=65535).contains(&p));
    let host_ok = !host.is_empty()
        && !host
            .chars()
            .any(|c| c.is_whitespace() || c.is_control() || c == '/')
        && if host.starts_with('[') {
            host.ends_with(']') && host.len() > 2
        } else {
            !host.contains(':')
        };
    port_ok && host_ok
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn payload_index_form() {
        for ok in ["39-0-7", "0-0-0", "52-0-0", "4294967295-1-2"] {
            assert!(is_payload_index(ok), "{ok}");
        }
        for bad in [
            "",
            "39-0",
            "39-0-7-1",
            "39--7",
            "a-0-7",
            "-1-0-7",
            "+1-0-7",
            " 39-0-7",
            "4294967296-0-0",
            "39-0-7 ",
        ] {
            assert!(!is_payload_index(bad), "{bad}");
        }
    }

    #[test]
    fn host_port_form() {
        for ok in [
            "mqtt.dji.com:8883",
            "192.0.2.1:8883",
            "[::1]:1883",
            "h:1",
            "h:65535",
        ] {
            assert!(is_host_port(ok), "{ok}");
        }
        for bad in [
            "",
            "mqtt.dji.com",
            ":8883",
            "h:0",
            "h:65536",
            "h:",
            "h:+1",
            "h:-1",
            "tcp://h:1883",
            "a b:1",
            "::1:1883",
            "[]:1",
            "h:123456",
            "h:88a",
        ] {
            assert!(!is_host_port(bad), "{bad}");
        }
    }

    #[test]
    fn int_rules() {
        assert_eq!(int_value(&json!(5), "f", 0..=9), Ok(5));
        assert_eq!(
            int_value(&json!(1.5), "f", 0..=9).unwrap_err().code,
            WRONG_TYPE
        );
        assert_eq!(
            int_value(&json!(1.0), "f", 0..=9).unwrap_err().code,
            WRONG_TYPE
        );
        assert_eq!(
            int_value(&json!("5"), "f", 0..=9).unwrap_err().code,
            WRONG_TYPE
        );
        assert_eq!(
            int_value(&json!(u64::MAX), "f", 0..=9).unwrap_err().code,
            OUT_OF_RANGE
        );
        let e = int_value(&json!(-1), "f", 0..=9).unwrap_err();
        assert_eq!((e.code, e.reason.as_str()), (OUT_OF_RANGE, "below min 0"));
    }

    #[test]
    fn num_rules() {
        assert_eq!(num_value(&json!(5), "f", 0.0, 9.0), Ok(5.0));
        assert_eq!(
            num_value(&json!(u64::MAX), "f", 0.0, f64::MAX),
            Ok(u64::MAX as f64)
        );
        assert_eq!(
            num_value(&json!(true), "f", 0.0, 9.0).unwrap_err().code,
            WRONG_TYPE
        );
        let e = num_value(&json!(9.5), "f", 0.0, 9.0).unwrap_err();
        assert_eq!((e.code, e.reason.as_str()), (OUT_OF_RANGE, "above max 9"));
        // A serde_json Number cannot hold NaN/inf (json! turns NaN into null, which is
        // not a number): the finiteness check in num_value is defence in depth.
        assert_eq!(
            num_value(&json!(f64::NAN), "f", 0.0, 9.0).unwrap_err().code,
            WRONG_TYPE
        );
    }

    #[test]
    fn enum_int_rejects_floats_and_strangers() {
        let table = [(0, 'a'), (1, 'b')];
        assert_eq!(enum_int_value(&json!(1), "f", &table), Ok('b'));
        assert_eq!(
            enum_int_value(&json!(1.0), "f", &table).unwrap_err().code,
            WRONG_TYPE
        );
        assert_eq!(
            enum_int_value(&json!(2), "f", &table).unwrap_err().code,
            NOT_IN_ENUM
        );
        assert_eq!(
            enum_int_value(&json!(u64::MAX), "f", &table)
                .unwrap_err()
                .code,
            NOT_IN_ENUM
        );
    }

    #[test]
    fn clip_keeps_char_boundaries() {
        assert_eq!(clip("abc", 5), "abc");
        assert_eq!(clip("abcdef", 3), "abc");
        assert_eq!(clip("aé", 2), "a");
    }
}
