//! Field primitives of the 64-byte payload: little-endian integers at fixed offsets,
//! the fixed-point conversions and zero-padded names.
//!
//! Fixed point (FACTS.md): angles (radians), temperatures, lat/lon/alt, distance and
//! FOV are `i32 = value × 1000`; normalised x/y offsets are `i16 = value × 32767`;
//! thresholds and overlaps are `u8 = value × 255`. Encoding rounds to nearest and
//! saturates (NaN → 0); `validate()` refuses such values before they are sent.

use crate::DATA_LEN;

pub(crate) type Data = [u8; DATA_LEN];

pub(crate) fn get<const N: usize>(d: &Data, at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    out.copy_from_slice(&d[at..at + N]);
    out
}

pub(crate) fn u16_at(d: &Data, at: usize) -> u16 {
    u16::from_le_bytes(get(d, at))
}
pub(crate) fn i16_at(d: &Data, at: usize) -> i16 {
    i16::from_le_bytes(get(d, at))
}
pub(crate) fn u32_at(d: &Data, at: usize) -> u32 {
    u32::from_le_bytes(get(d, at))
}
pub(crate) fn i32_at(d: &Data, at: usize) -> i32 {
    i32::from_le_bytes(get(d, at))
}

pub(crate) fn put(d: &mut Data, at: usize, bytes: &[u8]) {
    d[at..at + bytes.len()].copy_from_slice(bytes);
}

/// `i32 × 1000` → value.
pub fn from_milli(raw: i32) -> f64 {
    f64::from(raw) / 1000.0
}
/// value → `i32 × 1000`, rounded, saturating, NaN → 0.
pub fn to_milli(value: f64) -> i32 {
    (value * 1000.0).round() as i32
}
/// `i16 × 32767` → normalised offset.
pub fn from_offset(raw: i16) -> f64 {
    f64::from(raw) / 32767.0
}
/// normalised offset → `i16 × 32767`, rounded, saturating, NaN → 0.
pub fn to_offset(value: f64) -> i16 {
    (value * 32767.0).round() as i16
}
/// `u8 × 255` → ratio.
pub fn from_ratio(raw: u8) -> f64 {
    f64::from(raw) / 255.0
}
/// ratio → `u8 × 255`, rounded, saturating, NaN → 0.
pub fn to_ratio(value: f64) -> u8 {
    (value * 255.0).round() as u8
}

/// Why text does not fit a name field.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    #[error("name of {len} bytes is longer than {max}")]
    TooLong { len: usize, max: usize },
    #[error("name contains a NUL byte")]
    Nul,
    #[error("name is not valid UTF-8")]
    NotUtf8,
}

/// A C `char[N]` name, zero padded (`N` = 8 for stream names, 16 for model names).
/// All `N` bytes may be used (then there is no terminator). On reading, the name
/// ends at the first NUL and anything after it is ignored.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct FixedName<const N: usize> {
    bytes: [u8; N],
    len: usize,
}

/// A stream name, `char[8]`.
pub type StreamName = FixedName<8>;
/// A model name, `char[16]`.
pub type ModelName = FixedName<16>;

impl<const N: usize> FixedName<N> {
    pub fn new(name: &str) -> Result<Self, NameError> {
        if name.len() > N {
            return Err(NameError::TooLong {
                len: name.len(),
                max: N,
            });
        }
        if name.bytes().any(|b| b == 0) {
            return Err(NameError::Nul);
        }
        let mut bytes = [0u8; N];
        bytes[..name.len()].copy_from_slice(name.as_bytes());
        Ok(FixedName {
            bytes,
            len: name.len(),
        })
    }

    /// The empty name (all zeros).
    pub fn empty() -> Self {
        FixedName {
            bytes: [0; N],
            len: 0,
        }
    }

    /// From the wire: up to the first NUL, must be UTF-8.
    pub fn from_wire(raw: &[u8]) -> Result<Self, NameError> {
        let raw = &raw[..N.min(raw.len())];
        let len = raw.iter().position(|&b| b == 0).unwrap_or(raw.len());
        let text = std::str::from_utf8(&raw[..len]).map_err(|_| NameError::NotUtf8)?;
        Self::new(text)
    }

    /// The zero-padded wire bytes.
    pub fn wire(&self) -> [u8; N] {
        self.bytes
    }

    pub fn as_str(&self) -> &str {
        // `new` only stores the bytes of a `&str`.
        std::str::from_utf8(&self.bytes[..self.len]).unwrap_or_default()
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl<const N: usize> Default for FixedName<N> {
    fn default() -> Self {
        Self::empty()
    }
}

impl<const N: usize> std::fmt::Debug for FixedName<N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

impl<const N: usize> std::fmt::Display for FixedName<N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}
