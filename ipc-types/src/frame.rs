//! Camera frames: the header that travels with every frame's pixels.
//!
//! A frame is an iceoryx2 slice sample (`[u8]`, up to 1920×1080 RGB24 = 6,220,800
//! bytes) whose iceoryx2 *user header* is a [`FrameHeader`]. The pixels are written
//! in place in shared memory by the camera and read in place by every consumer; no
//! process copies them. Publishing and receiving live in `skymesh-runtime`
//! (`Bus::frame_publisher`, `Bus::frame_subscriber`); this module only defines the
//! layout and checks it.
//!
//! Topic: [`crate::topics::camera_frames`].

use iceoryx2::prelude::ZeroCopySend;

use crate::header::SampleHeader;
use crate::wire_enum;

/// The largest frame the stack carries: 1920×1080 RGB24.
pub const MAX_FRAME_LEN: usize = 1920 * 1080 * 3;

wire_enum! {
    /// How the pixels of a frame are laid out.
    pub enum PixelFormat: u8 {
        /// 3 bytes per pixel, R G B, rows `stride` bytes apart.
        Rgb24 = 1 => "rgb24",
        /// A luma plane of `height` rows, then an interleaved CbCr plane of
        /// `height / 2` rows, both `stride` bytes apart (width and height even).
        Nv12 = 2 => "nv12",
    }
}

wire_enum! {
    /// The projection the intrinsics describe.
    pub enum LensModel: u8 {
        /// Pinhole with radial-tangential distortion `k1, k2, p1, p2` in `k`.
        Pinhole = 0 => "pinhole",
        /// Equidistant fisheye (OpenCV `fisheye`): θ_d = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸).
        Fisheye = 1 => "fisheye",
    }
}

/// The camera's intrinsic calibration at capture (pixels of this frame).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct CameraIntrinsics {
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    /// Distortion coefficients k1..k4 (meaning per [`LensModel`]).
    pub k: [f32; 4],
    /// [`LensModel`] as stored on the wire.
    pub lens_model: u8,
    /// 1 if the intrinsics are calibrated; 0 = unknown (all fields zero).
    pub valid: u8,
    pub reserved: [u8; 2],
}
crate::assert_layout!(CameraIntrinsics, size = 36, align = 4);

/// Where the vehicle was, and how it was oriented, when the frame was captured.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct CapturePose {
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// The **camera's** orientation at capture (vehicle attitude × gimbal/mount): a
    /// unit quaternion `[w, x, y, z]` rotating camera-frame vectors (x along the
    /// optical axis, y image right, z image down) into NED. What geolocation needs;
    /// the vehicle's heading is [`FrameHeader::vehicle_heading_deg`].
    pub attitude_q: [f32; 4],
    /// Altitude above mean sea level, metres.
    pub alt_m: f32,
    /// 1 if the pose was known at capture; 0 = no pose (all fields zero).
    pub valid: u8,
    pub reserved: [u8; 3],
}
crate::assert_layout!(CapturePose, size = 40, align = 8);

/// The iceoryx2 user header of every frame sample.
///
/// `header` is stamped by the runtime's frame publisher (sequence, publish time,
/// publisher id), as for every other sample; `payload_len` too (the slice length).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.FrameHeader.v1")]
#[repr(C)]
pub struct FrameHeader {
    pub header: SampleHeader,
    /// The camera's frame counter (driver sequence), distinct from `header.seq`.
    pub frame_seq: u64,
    /// `CLOCK_MONOTONIC` ns of capture (start of exposure if the driver knows it).
    pub capture_mono_ns: u64,
    /// Unix time ns of capture (`CLOCK_REALTIME`), 0 if unknown.
    pub capture_unix_ns: u64,
    pub width: u32,
    pub height: u32,
    /// Bytes from one row to the next (≥ width × bytes per pixel of the first plane).
    pub stride: u32,
    /// Bytes of pixel data (the slice length).
    pub payload_len: u32,
    /// [`PixelFormat`] as stored on the wire.
    pub pixel_format: u8,
    pub reserved: [u8; 7],
    pub intrinsics: CameraIntrinsics,
    /// The vehicle's heading at capture, degrees from true north (0..360), for angles
    /// relative to the nose; meaningful when `pose.valid` is 1.
    pub vehicle_heading_deg: f32,
    pub pose: CapturePose,
}
crate::assert_layout!(FrameHeader, size = 24 + 48 + 36 + 4 + 40, align = 8);

crate::impl_sample!(FrameHeader);

/// Why a frame header does not describe its pixels.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameHeaderError {
    #[error("unknown pixel format {0}")]
    PixelFormat(u8),
    #[error("unknown lens model {0}")]
    LensModel(u8),
    #[error("bad geometry {width}x{height} stride {stride} for {format}")]
    Geometry {
        format: PixelFormat,
        width: u32,
        height: u32,
        stride: u32,
    },
    #[error("payload of {actual} bytes, {format} {width}x{height} stride {stride} needs {needed}")]
    Length {
        format: PixelFormat,
        width: u32,
        height: u32,
        stride: u32,
        needed: u64,
        actual: u64,
    },
    #[error("header says {header} bytes of pixels, the sample holds {slice}")]
    PayloadLen { header: u32, slice: u64 },
    #[error("non-finite or negative intrinsics")]
    Intrinsics,
    #[error("non-finite pose")]
    Pose,
}

impl PixelFormat {
    /// Bytes of one pixel of the first plane.
    pub const fn bytes_per_pixel(self) -> u32 {
        match self {
            PixelFormat::Rgb24 => 3,
            PixelFormat::Nv12 => 1,
        }
    }

    /// Bytes a `width × height` frame with rows `stride` apart occupies, or `None` if
    /// that geometry is impossible in this format.
    pub fn frame_len(self, width: u32, height: u32, stride: u32) -> Option<u64> {
        if width == 0 || height == 0 {
            return None;
        }
        if u64::from(stride) < u64::from(width) * u64::from(self.bytes_per_pixel()) {
            return None;
        }
        let (w, h, s) = (u64::from(width), u64::from(height), u64::from(stride));
        match self {
            PixelFormat::Rgb24 => Some(s * h),
            PixelFormat::Nv12 if w % 2 == 0 && h % 2 == 0 => Some(s * h + s * (h / 2)),
            PixelFormat::Nv12 => None,
        }
    }
}

impl FrameHeader {
    pub fn pixel_format(&self) -> Result<PixelFormat, FrameHeaderError> {
        PixelFormat::try_from(self.pixel_format)
            .map_err(|_| FrameHeaderError::PixelFormat(self.pixel_format))
    }

    pub fn lens_model(&self) -> Result<LensModel, FrameHeaderError> {
        LensModel::try_from(self.intrinsics.lens_model)
            .map_err(|_| FrameHeaderError::LensModel(self.intrinsics.lens_model))
    }

    /// Sets width, height, stride and format together.
    pub fn set_geometry(&mut self, format: PixelFormat, width: u32, height: u32, stride: u32) {
        self.pixel_format = format.to_wire();
        self.width = width;
        self.height = height;
        self.stride = stride;
    }

    /// Checks that the header is consistent and describes `payload_len` bytes of
    /// pixels (what a reader must do before trusting it: the header comes from another
    /// process).
    pub fn validate(&self, payload_len: usize) -> Result<PixelFormat, FrameHeaderError> {
        let format = self.pixel_format()?;
        self.lens_model()?;
        let needed = format
            .frame_len(self.width, self.height, self.stride)
            .ok_or(FrameHeaderError::Geometry {
                format,
                width: self.width,
                height: self.height,
                stride: self.stride,
            })?;
        let actual = payload_len as u64;
        if u64::from(self.payload_len) != actual {
            return Err(FrameHeaderError::PayloadLen {
                header: self.payload_len,
                slice: actual,
            });
        }
        if needed != actual {
            return Err(FrameHeaderError::Length {
                format,
                width: self.width,
                height: self.height,
                stride: self.stride,
                needed,
                actual,
            });
        }
        let i = &self.intrinsics;
        let finite = [i.fx, i.fy, i.cx, i.cy]
            .iter()
            .chain(i.k.iter())
            .all(|v| v.is_finite());
        if !finite || i.fx < 0.0 || i.fy < 0.0 {
            return Err(FrameHeaderError::Intrinsics);
        }
        let p = &self.pose;
        let pose_finite = p.lat_deg.is_finite()
            && p.lon_deg.is_finite()
            && p.alt_m.is_finite()
            && p.attitude_q.iter().all(|v| v.is_finite());
        if !pose_finite {
            return Err(FrameHeaderError::Pose);
        }
        Ok(format)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rgb(width: u32, height: u32) -> FrameHeader {
        let mut h = FrameHeader::default();
        h.set_geometry(PixelFormat::Rgb24, width, height, width * 3);
        h.payload_len = width * height * 3;
        h
    }

    #[test]
    fn full_hd_rgb_is_the_largest_frame() {
        assert_eq!(
            PixelFormat::Rgb24.frame_len(1920, 1080, 1920 * 3),
            Some(MAX_FRAME_LEN as u64)
        );
        assert_eq!(
            PixelFormat::Nv12.frame_len(1920, 1080, 1920),
            Some(1920 * 1080 * 3 / 2)
        );
        assert_eq!(PixelFormat::Nv12.frame_len(3, 2, 4), None);
        assert_eq!(PixelFormat::Rgb24.frame_len(10, 10, 29), None);
        assert_eq!(PixelFormat::Rgb24.frame_len(0, 10, 30), None);
    }

    #[test]
    fn a_consistent_header_validates() {
        let h = rgb(640, 480);
        assert_eq!(h.validate(640 * 480 * 3), Ok(PixelFormat::Rgb24));
    }

    #[test]
    fn inconsistent_headers_are_refused() {
        let h = rgb(640, 480);
        assert!(matches!(
            h.validate(640 * 480 * 3 - 1),
            Err(FrameHeaderError::PayloadLen { .. })
        ));
        let mut short = h;
        short.payload_len -= 1;
        assert!(matches!(
            short.validate(640 * 480 * 3 - 1),
            Err(FrameHeaderError::Length { .. })
        ));
        let mut bad = h;
        bad.pixel_format = 9;
        assert_eq!(
            bad.validate(640 * 480 * 3),
            Err(FrameHeaderError::PixelFormat(9))
        );
        let mut bad = h;
        bad.intrinsics.lens_model = 7;
        assert_eq!(
            bad.validate(640 * 480 * 3),
            Err(FrameHeaderError::LensModel(7))
        );
        let mut bad = h;
        bad.intrinsics.fx = f32::NAN;
        assert_eq!(
            bad.validate(640 * 480 * 3),
            Err(FrameHeaderError::Intrinsics)
        );
        let mut bad = h;
        bad.pose.lat_deg = f64::INFINITY;
        assert_eq!(bad.validate(640 * 480 * 3), Err(FrameHeaderError::Pose));
        let mut bad = h;
        bad.payload_len += 3;
        assert!(bad.validate(640 * 480 * 3).is_err());
    }
}
