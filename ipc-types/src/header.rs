//! The header every sample carries, and the ids of the services that publish.

use iceoryx2::prelude::ZeroCopySend;

use crate::wire_enum;

wire_enum! {
    /// Which kind of skymesh process published a sample.
    pub enum ServiceId: u16 {
        Unknown = 0 => "unknown",
        Supervisor = 1 => "supervisor",
        AutopilotLink = 2 => "autopilot-link",
        VehicleSim = 3 => "vehicle-sim",
        ShotEngine = 4 => "shot-engine",
        SwarmQueue = 5 => "swarm-queue",
        Camera = 6 => "camera",
        VisionPipeline = 7 => "vision-pipeline",
        SoloGateway = 8 => "solo-gateway",
        DjiGateway = 9 => "dji-gateway",
        DigiviewGateway = 10 => "digiview-gateway",
        GroundcontrolGateway = 11 => "groundcontrol-gateway",
        ImcGateway = 12 => "imc-gateway",
        MqttBroker = 13 => "mqtt-broker",
        Hardware = 14 => "hardware",
        /// Command-line tools and tests that publish on the bus.
        Tool = 100 => "tool",
    }
}

/// Carried as the first field of every sample.
///
/// `stamp_ns` is `CLOCK_MONOTONIC` at publish, comparable across the processes of
/// one machine, so any consumer can compute a sample's age.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[repr(C)]
pub struct SampleHeader {
    /// Per-publisher sequence number, starting at 1 (0 = never published).
    pub seq: u64,
    /// `CLOCK_MONOTONIC` nanoseconds when the sample was published.
    pub stamp_ns: u64,
    /// [`ServiceId`] of the publishing process, as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::ServiceId>")
    )]
    pub service: u16,
    /// Instance of that service (e.g. the vehicle-sim index in a swarm), 0 if single.
    pub instance: u16,
    /// Reserved, zero.
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: u32,
}
crate::assert_layout!(SampleHeader, size = 24, align = 8);

impl SampleHeader {
    /// The publishing service, if its id is known to this build.
    pub fn service_id(&self) -> Result<ServiceId, crate::UnknownValue> {
        ServiceId::try_from(self.service)
    }

    /// Age of the sample at `now_ns` (same clock), saturating at zero.
    pub fn age_ns(&self, now_ns: u64) -> u64 {
        now_ns.saturating_sub(self.stamp_ns)
    }
}

/// A type that can travel on the skymesh bus: fixed layout, plain data, with a header.
///
/// The runtime's publishers fill the header; subscribers use it for age and gaps.
pub trait Sample: ZeroCopySend + Copy + Default + core::fmt::Debug + Send + 'static {
    fn header(&self) -> &SampleHeader;
    fn header_mut(&mut self) -> &mut SampleHeader;
}

/// Implements [`Sample`] for a struct whose first field is `header: SampleHeader`.
#[macro_export]
macro_rules! impl_sample {
    ($($ty:ty),+ $(,)?) => {$(
        impl $crate::header::Sample for $ty {
            fn header(&self) -> &$crate::header::SampleHeader { &self.header }
            fn header_mut(&mut self) -> &mut $crate::header::SampleHeader { &mut self.header }
        }
    )+};
}
