//! skymesh sample types and service names.
//!
//! Everything that crosses a process boundary on the skymesh bus is defined here:
//! plain `#[repr(C)]` data with fixed capacity (no heap, no pointers), enums stored as
//! integers and checked at the edge, a versioned iceoryx2 `type_name` and a
//! compile-time size/alignment assertion. Change a layout → bump the version in its
//! `type_name` (iceoryx2 compares only name, size and alignment across processes).
//!
//! This crate does no I/O and has no runtime: it is shared by every service, by the
//! supervisor and by the tests.
#![deny(unsafe_code)]

pub mod arbiter;
pub mod camera;
pub mod camera_demand;
pub mod command;
pub mod fixed;
pub mod frame;
pub mod hardware;
pub mod header;
#[cfg(feature = "serde")]
pub mod json;
pub mod payload;
pub mod service;
pub mod shot;
pub mod shot_api;
pub mod shot_fence;
pub mod swarm;
pub mod task;
pub mod topics;
pub mod vehicle;
pub mod view;
pub mod vision;

pub use arbiter::{
    ArbiterEvent, ArbiterEventKind, AuthorityChange, AuthorityState, FenceError, FenceKind,
    FencePolygon, GeofenceSet, NO_HOLDER,
};
pub use camera::{SceneTruth, TargetTruth, SCENE_MAX_TARGETS};
pub use camera_demand::{CameraDemand, CAMERA_DEMAND_LEASE_NS};
pub use command::{
    AckResult, AuthorityDomain, CameraModeKind, Command, CommandAck, CommandError, CommandKind,
    CommandSource, FocusMode, RefusalReason, VehicleCommand, ZoomMode,
};
pub use fixed::FixedStr;
pub use frame::{
    CameraIntrinsics, CapturePose, FrameHeader, FrameHeaderError, LensModel, PixelFormat,
    MAX_FRAME_LEN,
};
pub use hardware::{
    GpioEntry, HardwareOp, HardwareReply, HardwareRequest, HardwareResult, HardwareState, HwName,
    LcdOp, LedEntry, PowerChannelEntry, PowerChannelOp, SystemPowerOp, HW_MAX_ENTRIES,
    HW_NAME_CAPACITY, LCD_LINE_CAPACITY,
};
pub use header::{Sample, SampleHeader, ServiceId};
pub use payload::{GoProStatus, PayloadState};
pub use service::{ServiceHealth, ServiceState, ServiceStats, StatEntry, StatKind};
pub use shot::{AppSession, Button, ButtonEvent, ButtonEventKind, ShotPhase, ShotStatus};
pub use shot_api::{
    ShotDecodeError, ShotEvent, ShotEventSample, ShotRequest, ShotRequestSample, SHOT_BODY_CAPACITY,
};
pub use shot_fence::{AppFencePolygon, AppGeofence};
pub use swarm::{
    drone_flags, swarm_flags, DroneState, SwarmCommand, SwarmCommandError, SwarmCommandKind,
    SwarmDrone, SwarmReply, SwarmResult, SwarmState, SwarmWatch, ALL_DRONES, SWARM_MAX_DRONES,
    SWARM_WATCH_LEASE_NS,
};
pub use task::{
    FlightTaskStatus, PoiReason, PoiTaskStatus, TaskEvent, TaskEventKind, TaskPoint, TaskRequest,
    TaskRequestKind, TaskResult, TASK_MAX_POINTS,
};
pub use topics::{Topic, TopicQos};
pub use vehicle::{FlightMode, GpsFix, VehicleState, VehicleStatus};
pub use view::{ReferenceFrame, TrackCommand, ViewControl, ViewControlKind, ViewReply};
pub use vision::{
    CropMode, SttMode, SttState, TargetingMode, VirtualCamState, VisionControl, VisionControlKind,
    VisionDemand, VisionDetection, VisionOrigin, VisionReply, VisionResult, VisionState,
    VisionStreamState, LOCK_PITCH, LOCK_ROLL, LOCK_YAW, VISION_DEMAND_LEASE_NS, VISION_MAX_CAMS,
    VISION_MAX_DETECTIONS, VISION_MAX_MODELS, VISION_MAX_STREAMS,
};

/// Declares a checked integer-backed enum: the wire holds the integer, the code sees
/// the enum, and `TryFrom<int>` refuses anything not listed.
#[macro_export]
macro_rules! wire_enum {
    ($(#[$meta:meta])* $vis:vis enum $name:ident : $repr:ty { $($(#[$vmeta:meta])* $variant:ident = $value:expr => $label:literal),+ $(,)? }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[repr($repr)]
        $vis enum $name { $($(#[$vmeta])* $variant = $value),+ }

        impl $name {
            /// Every variant, in declaration order.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];

            /// The integer stored on the wire.
            pub const fn to_wire(self) -> $repr { self as $repr }

            /// A stable lower-case name for logs and metric labels.
            pub fn as_str(self) -> &'static str {
                match self { $($name::$variant => $label),+ }
            }
        }

        impl TryFrom<$repr> for $name {
            type Error = $crate::UnknownValue;
            fn try_from(v: $repr) -> Result<Self, Self::Error> {
                match v {
                    $(x if x == $value => Ok($name::$variant),)+
                    other => Err($crate::UnknownValue { type_name: stringify!($name), value: other as i64 }),
                }
            }
        }

        impl $crate::WireEnum for $name {
            type Repr = $repr;
            const TYPE_NAME: &'static str = stringify!($name);
            fn name_of(raw: $repr) -> Option<&'static str> {
                <$name>::try_from(raw).ok().map(<$name>::as_str)
            }
            fn from_name(name: &str) -> Option<$repr> {
                <$name>::ALL.iter().find(|v| v.as_str() == name).map(|v| v.to_wire())
            }
            fn names() -> Vec<&'static str> {
                <$name>::ALL.iter().map(|v| v.as_str()).collect()
            }
        }

        impl core::fmt::Display for $name {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.write_str(self.as_str())
            }
        }
    };
}

/// An enum declared with [`wire_enum!`], seen through the integer stored on the wire:
/// what JSON (feature `serde`) needs to write such a field as a name.
pub trait WireEnum: Copy + 'static {
    /// The integer type on the wire.
    type Repr: Copy + Into<i64> + TryFrom<i64>;
    /// The enum's Rust name.
    const TYPE_NAME: &'static str;
    /// The stable name of the variant stored as `raw`, if there is one.
    fn name_of(raw: Self::Repr) -> Option<&'static str>;
    /// The integer of the variant named `name`.
    fn from_name(name: &str) -> Option<Self::Repr>;
    /// Every variant's name, in declaration order.
    fn names() -> Vec<&'static str>;
}

/// An integer on the wire that names no variant of the enum it should hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UnknownValue {
    pub type_name: &'static str,
    pub value: i64,
}

impl core::fmt::Display for UnknownValue {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{} has no variant with value {}",
            self.type_name, self.value
        )
    }
}

impl std::error::Error for UnknownValue {}

/// Compile-time layout assertion used next to every sample type.
#[macro_export]
macro_rules! assert_layout {
    ($ty:ty, size = $size:expr, align = $align:expr) => {
        const _: () = assert!(
            core::mem::size_of::<$ty>() == $size,
            "layout changed: bump the type_name version"
        );
        const _: () = assert!(
            core::mem::align_of::<$ty>() == $align,
            "alignment changed: bump the type_name version"
        );
    };
}
