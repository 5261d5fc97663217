//! The bytes of a sample body: a little-endian [`Writer`] and [`Reader`], and
//! [`Field`], how one field of a kind is written, read and checked.

use super::{
    ButtonSetting, GoProState, Location, ShotDecodeError, SplinePoint, SHOT_BODY_CAPACITY,
};

pub(super) fn check_f32(field: &str, v: f32) -> Result<f32, ShotDecodeError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(ShotDecodeError::Invalid(format!(
            "{field} is not finite ({v})"
        )))
    }
}

fn check_f64(field: &str, v: f64) -> Result<f64, ShotDecodeError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(ShotDecodeError::Invalid(format!(
            "{field} is not finite ({v})"
        )))
    }
}

pub(super) fn check_lat(field: &str, v: f64) -> Result<f64, ShotDecodeError> {
    let v = check_f64(field, v)?;
    if (-90.0..=90.0).contains(&v) {
        Ok(v)
    } else {
        Err(ShotDecodeError::Invalid(format!(
            "{field} {v} is outside -90..=90"
        )))
    }
}

pub(super) fn check_lon(field: &str, v: f64) -> Result<f64, ShotDecodeError> {
    let v = check_f64(field, v)?;
    if (-180.0..=180.0).contains(&v) {
        Ok(v)
    } else {
        Err(ShotDecodeError::Invalid(format!(
            "{field} {v} is outside -180..=180"
        )))
    }
}

/// Little-endian writer into a fixed body. Every fixed-size kind fits with room
/// to spare (the largest, a keypoint, is 44 bytes); text is cut to what is left.
pub(super) struct Writer {
    pub(super) buf: [u8; SHOT_BODY_CAPACITY],
    pub(super) len: usize,
}

impl Default for Writer {
    fn default() -> Self {
        Writer {
            buf: [0; SHOT_BODY_CAPACITY],
            len: 0,
        }
    }
}

impl Writer {
    fn bytes(&mut self, b: &[u8]) {
        let end = self.len + b.len();
        debug_assert!(end <= SHOT_BODY_CAPACITY, "fixed-size kinds fit");
        let end = end.min(SHOT_BODY_CAPACITY);
        let n = end - self.len;
        self.buf[self.len..end].copy_from_slice(&b[..n]);
        self.len = end;
    }

    /// The text, cut at a character boundary to the room left.
    fn text(&mut self, text: &str) {
        let mut end = text.len().min(SHOT_BODY_CAPACITY - self.len);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        self.bytes(&text.as_bytes()[..end]);
    }
}

/// Little-endian reader of a body; running out is a wrong length.
pub(super) struct Reader<'a> {
    kind: u16,
    rest: &'a [u8],
    len: usize,
}

impl<'a> Reader<'a> {
    pub(super) fn new(kind: u16, body: &'a [u8], len: u16) -> Result<Self, ShotDecodeError> {
        let len = usize::from(len);
        if len > body.len() {
            return Err(ShotDecodeError::WrongLength {
                kind,
                len,
                expected: body.len(),
            });
        }
        Ok(Reader {
            kind,
            rest: &body[..len],
            len,
        })
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], ShotDecodeError> {
        if self.rest.len() < N {
            return Err(ShotDecodeError::WrongLength {
                kind: self.kind,
                len: self.len,
                expected: self.len - self.rest.len() + N,
            });
        }
        let (head, tail) = self.rest.split_at(N);
        self.rest = tail;
        let mut out = [0; N];
        out.copy_from_slice(head);
        Ok(out)
    }

    /// The rest of the body as text (lossy UTF-8).
    fn text(&mut self) -> String {
        let s = String::from_utf8_lossy(self.rest).into_owned();
        self.rest = &[];
        s
    }

    /// Every byte must have been read.
    pub(super) fn finish<T>(self, v: T) -> Result<T, ShotDecodeError> {
        if self.rest.is_empty() {
            Ok(v)
        } else {
            Err(ShotDecodeError::WrongLength {
                kind: self.kind,
                len: self.len,
                expected: self.len - self.rest.len(),
            })
        }
    }
}

/// How one field of a kind's body is written and read back. `Self` names the
/// encoding, `Value` the Rust type it carries (a latitude is an `f64` written as
/// [`Lat`]); `label` names the field when a read value is refused.
pub(super) trait Field {
    type Value;
    fn put(v: &Self::Value, w: &mut Writer);
    fn take(r: &mut Reader<'_>, label: &str) -> Result<Self::Value, ShotDecodeError>;
}

/// Integers: little-endian, any value.
macro_rules! int_fields {
    ($($t:ty),*) => {$(
        impl Field for $t {
            type Value = $t;
            fn put(v: &$t, w: &mut Writer) {
                w.bytes(&v.to_le_bytes());
            }
            fn take(r: &mut Reader<'_>, _label: &str) -> Result<$t, ShotDecodeError> {
                Ok(<$t>::from_le_bytes(r.array()?))
            }
        }
    )*};
}
int_fields!(u8, u16, i16, u32, i32);

/// A finite `f32`.
impl Field for f32 {
    type Value = f32;
    fn put(v: &f32, w: &mut Writer) {
        w.bytes(&v.to_le_bytes());
    }
    fn take(r: &mut Reader<'_>, label: &str) -> Result<f32, ShotDecodeError> {
        check_f32(label, f32::from_le_bytes(r.array()?))
    }
}

/// A latitude: a finite `f64` within ±90°.
pub(super) enum Lat {}

impl Field for Lat {
    type Value = f64;
    fn put(v: &f64, w: &mut Writer) {
        w.bytes(&v.to_le_bytes());
    }
    fn take(r: &mut Reader<'_>, label: &str) -> Result<f64, ShotDecodeError> {
        check_lat(label, f64::from_le_bytes(r.array()?))
    }
}

/// A longitude: a finite `f64` within ±180°.
pub(super) enum Lon {}

impl Field for Lon {
    type Value = f64;
    fn put(v: &f64, w: &mut Writer) {
        w.bytes(&v.to_le_bytes());
    }
    fn take(r: &mut Reader<'_>, label: &str) -> Result<f64, ShotDecodeError> {
        check_lon(label, f64::from_le_bytes(r.array()?))
    }
}

/// One byte, 0 false.
impl Field for bool {
    type Value = bool;
    fn put(v: &bool, w: &mut Writer) {
        w.bytes(&[u8::from(*v)]);
    }
    fn take(r: &mut Reader<'_>, _label: &str) -> Result<bool, ShotDecodeError> {
        Ok(r.array::<1>()?[0] != 0)
    }
}

/// Raw bytes, read as one block.
impl<const N: usize> Field for [u8; N] {
    type Value = [u8; N];
    fn put(v: &[u8; N], w: &mut Writer) {
        w.bytes(v);
    }
    fn take(r: &mut Reader<'_>, _label: &str) -> Result<[u8; N], ShotDecodeError> {
        r.array()
    }
}

/// The rest of the body: cut to the room left, read as lossy UTF-8.
impl Field for String {
    type Value = String;
    fn put(v: &String, w: &mut Writer) {
        w.text(v);
    }
    fn take(r: &mut Reader<'_>, _label: &str) -> Result<String, ShotDecodeError> {
        Ok(r.text())
    }
}

/// A struct written as its fields in order: `Type { field: Encoding = "label", … }`
/// (the label only where the encoding checks the value).
macro_rules! record_field {
    ($Struct:ident { $($f:ident : $T:ty $(= $label:literal)?),* $(,)? }) => {
        impl Field for $Struct {
            type Value = $Struct;
            fn put(v: &$Struct, w: &mut Writer) {
                $(<$T as Field>::put(&v.$f, w);)*
            }
            fn take(r: &mut Reader<'_>, _label: &str) -> Result<$Struct, ShotDecodeError> {
                Ok($Struct {
                    $($f: <$T as Field>::take(r, concat!("" $(, $label)?))?,)*
                })
            }
        }
    };
}

record_field!(Location {
    lat_deg: Lat = "latitude",
    lon_deg: Lon = "longitude",
    alt_m: f32 = "altitude",
});

record_field!(ButtonSetting {
    button: i32,
    event: i32,
    shot: i32,
    mode: i32,
});

record_field!(SplinePoint {
    version: i16,
    abs_alt_ref_m: f32 = "abs_alt_ref",
    index: i32,
    lat_deg: Lat = "latitude",
    lon_deg: Lon = "longitude",
    alt_m: f32 = "altitude",
    pitch_deg: f32 = "pitch",
    yaw_deg: f32 = "yaw",
    u_position: f32 = "u_position",
    status: i16,
});

/// The 19 one-byte settings as one block, then the reserved bytes and words.
impl Field for GoProState {
    type Value = GoProState;
    fn put(s: &GoProState, w: &mut Writer) {
        w.bytes(&[
            s.version,
            s.model,
            s.status,
            s.recording,
            s.capture_mode,
            s.ntsc_pal,
            s.video_resolution,
            s.video_fps,
            s.video_fov,
            s.video_low_light,
            s.photo_resolution,
            s.photo_burst_rate,
            s.video_protune,
            s.video_white_balance,
            s.video_color,
            s.video_gain,
            s.video_sharpness,
            s.video_exposure,
            s.gimbal_enabled,
        ]);
        w.bytes(&s.extra_u8);
        for v in &s.extra_u16 {
            <u16 as Field>::put(v, w);
        }
    }
    fn take(r: &mut Reader<'_>, label: &str) -> Result<GoProState, ShotDecodeError> {
        let b: [u8; 19] = r.array()?;
        let extra_u8: [u8; 7] = r.array()?;
        let mut extra_u16 = [0u16; 5];
        for v in &mut extra_u16 {
            *v = <u16 as Field>::take(r, label)?;
        }
        Ok(GoProState {
            version: b[0],
            model: b[1],
            status: b[2],
            recording: b[3],
            capture_mode: b[4],
            ntsc_pal: b[5],
            video_resolution: b[6],
            video_fps: b[7],
            video_fov: b[8],
            video_low_light: b[9],
            photo_resolution: b[10],
            photo_burst_rate: b[11],
            video_protune: b[12],
            video_white_balance: b[13],
            video_color: b[14],
            video_gain: b[15],
            video_sharpness: b[16],
            video_exposure: b[17],
            gimbal_enabled: b[18],
            extra_u8,
            extra_u16,
        })
    }
}
