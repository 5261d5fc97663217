//! Little-endian field reader with the checks every family shares. Decoding has
//! already checked the value's length against the catalog, so running short is a
//! bug here, but it is still an error rather than a panic.

use std::fmt::Display;

use crate::catalog;
use crate::error::DecodeError;
use crate::MAX_SPEED_MPS;

/// Reads one value's fields in order and names the field in every error.
#[derive(Debug)]
pub(crate) struct Reader<'a> {
    msg_type: u32,
    total: usize,
    rest: &'a [u8],
}

pub(crate) fn name_of(msg_type: u32) -> &'static str {
    catalog::message_name(msg_type).unwrap_or("unknown")
}

pub(crate) fn invalid(msg_type: u32, what: impl Into<String>) -> DecodeError {
    DecodeError::InvalidValue {
        msg_type,
        name: name_of(msg_type),
        what: what.into(),
    }
}

impl<'a> Reader<'a> {
    pub fn new(msg_type: u32, value: &'a [u8]) -> Self {
        Reader {
            msg_type,
            total: value.len(),
            rest: value,
        }
    }

    pub fn msg_type(&self) -> u32 {
        self.msg_type
    }

    /// Consumes and returns everything not read yet (variable-length values).
    pub fn take_rest(&mut self) -> &'a [u8] {
        std::mem::take(&mut self.rest)
    }

    pub fn invalid(&self, what: impl Into<String>) -> DecodeError {
        invalid(self.msg_type, what)
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        match self.rest.split_first_chunk::<N>() {
            Some((head, tail)) => {
                self.rest = tail;
                Ok(*head)
            }
            None => Err(DecodeError::WrongLength {
                msg_type: self.msg_type,
                name: name_of(self.msg_type),
                expected: self.total - self.rest.len() + N,
                got: self.total,
            }),
        }
    }

    pub fn u8(&mut self) -> Result<u8, DecodeError> {
        Ok(self.take::<1>()?[0])
    }
    pub fn u16(&mut self) -> Result<u16, DecodeError> {
        self.take().map(u16::from_le_bytes)
    }
    pub fn i16(&mut self) -> Result<i16, DecodeError> {
        self.take().map(i16::from_le_bytes)
    }
    pub fn u32(&mut self) -> Result<u32, DecodeError> {
        self.take().map(u32::from_le_bytes)
    }
    pub fn i32(&mut self) -> Result<i32, DecodeError> {
        self.take().map(i32::from_le_bytes)
    }
    pub fn bytes<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        self.take()
    }

    /// An integer field restricted to `lo..=hi`.
    pub fn in_range<T: PartialOrd + Display + Copy>(
        &self,
        field: &str,
        v: T,
        lo: T,
        hi: T,
    ) -> Result<T, DecodeError> {
        if v < lo || v > hi {
            return Err(self.invalid(format!("{field} {v} is outside {lo}..={hi}")));
        }
        Ok(v)
    }

    pub fn u8_in(&mut self, field: &str, lo: u8, hi: u8) -> Result<u8, DecodeError> {
        let v = self.u8()?;
        self.in_range(field, v, lo, hi)
    }
    pub fn u16_in(&mut self, field: &str, lo: u16, hi: u16) -> Result<u16, DecodeError> {
        let v = self.u16()?;
        self.in_range(field, v, lo, hi)
    }
    pub fn u32_in(&mut self, field: &str, lo: u32, hi: u32) -> Result<u32, DecodeError> {
        let v = self.u32()?;
        self.in_range(field, v, lo, hi)
    }
    pub fn i32_in(&mut self, field: &str, lo: i32, hi: i32) -> Result<i32, DecodeError> {
        let v = self.i32()?;
        self.in_range(field, v, lo, hi)
    }

    /// A finite f32 (NaN and ±∞ are refused).
    pub fn f32(&mut self, field: &str) -> Result<f32, DecodeError> {
        let v = f32::from_le_bytes(self.take()?);
        if !v.is_finite() {
            return Err(self.invalid(format!("{field} is not finite ({v})")));
        }
        Ok(v)
    }

    /// A finite f64.
    pub fn f64(&mut self, field: &str) -> Result<f64, DecodeError> {
        let v = f64::from_le_bytes(self.take()?);
        if !v.is_finite() {
            return Err(self.invalid(format!("{field} is not finite ({v})")));
        }
        Ok(v)
    }

    /// A finite f32 within `lo..=hi`.
    pub fn f32_in(&mut self, field: &str, lo: f32, hi: f32) -> Result<f32, DecodeError> {
        let v = self.f32(field)?;
        self.in_range(field, v, lo, hi)
    }

    /// A speed in m/s, either sign, at most [`MAX_SPEED_MPS`] in magnitude.
    pub fn speed(&mut self, field: &str) -> Result<f32, DecodeError> {
        self.f32_in(field, -MAX_SPEED_MPS, MAX_SPEED_MPS)
    }

    /// A latitude in degrees, |lat| ≤ 90.
    pub fn lat(&mut self, field: &str) -> Result<f64, DecodeError> {
        let v = self.f64(field)?;
        self.in_range(field, v, -90.0, 90.0)
    }

    /// A longitude in degrees, |lon| ≤ 180.
    pub fn lon(&mut self, field: &str) -> Result<f64, DecodeError> {
        let v = self.f64(field)?;
        self.in_range(field, v, -180.0, 180.0)
    }

    /// Every byte must have been read (the length check makes this hold; kept so a
    /// layout mistake in a family file shows up as an error in its tests).
    pub fn finish<T>(self, v: T) -> Result<T, DecodeError> {
        if self.rest.is_empty() {
            Ok(v)
        } else {
            Err(DecodeError::WrongLength {
                msg_type: self.msg_type,
                name: name_of(self.msg_type),
                expected: self.total - self.rest.len(),
                got: self.total,
            })
        }
    }
}

/// Checks a latitude/longitude pair held outside a [`Reader`] (JSON, f32 fields).
pub(crate) fn check_lat_lon(
    msg_type: u32,
    what: &str,
    lat: f64,
    lon: f64,
) -> Result<(), DecodeError> {
    if !lat.is_finite() || !lon.is_finite() || lat.abs() > 90.0 || lon.abs() > 180.0 {
        return Err(invalid(
            msg_type,
            format!("{what} ({lat}, {lon}) is not a valid latitude/longitude"),
        ));
    }
    Ok(())
}
