//! What the command arbiter (inside `autopilot-link`) publishes and listens to
//! besides commands: who holds authority, what it did on its own, and the geofence.

use iceoryx2::prelude::ZeroCopySend;

use crate::command::CommandSource;
use crate::fixed::FixedStr;
use crate::header::SampleHeader;
use crate::wire_enum;

/// `holder` value meaning nobody holds that authority.
pub const NO_HOLDER: u8 = 255;

wire_enum! {
    /// Why authority last changed hands.
    pub enum AuthorityChange: u8 {
        /// Nobody has held it yet.
        None = 0 => "none",
        /// Granted on an explicit grab (nobody of higher priority held it).
        Granted = 1 => "granted",
        /// Taken by a higher-priority source; `previous` lost it.
        Preempted = 2 => "preempted",
        /// Given back explicitly.
        Released = 3 => "released",
        /// The holder's command stream went quiet for the configured time.
        Timeout = 4 => "timeout",
        /// An emergency stop gave it to the safety source.
        Emergency = 5 => "emergency",
        /// The autopilot link went down; nobody holds authority until it is back.
        LinkLost = 6 => "link_lost",
    }
}

/// Who holds flight and payload authority over one vehicle, published by the
/// arbiter on every change and once a second (history 1: a late subscriber sees the
/// current holder at once). A pre-empted holder learns it here.
///
/// Topic: [`crate::topics::vehicle_authority`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[type_name("skymesh.AuthorityState.v2")]
#[repr(C)]
pub struct AuthorityState {
    pub header: SampleHeader,
    pub vehicle_id: u8,
    /// [`CommandSource`] holding flight authority, or [`NO_HOLDER`].
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CommandSource>")
    )]
    pub flight_holder: u8,
    /// [`CommandSource`] that held flight authority before the last change, or [`NO_HOLDER`].
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CommandSource>")
    )]
    pub flight_previous: u8,
    /// [`AuthorityChange`] of the last flight-authority change.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::AuthorityChange>")
    )]
    pub flight_change: u8,
    /// [`CommandSource`] holding payload authority, or [`NO_HOLDER`].
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CommandSource>")
    )]
    pub payload_holder: u8,
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CommandSource>")
    )]
    pub payload_previous: u8,
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::AuthorityChange>")
    )]
    pub payload_change: u8,
    /// 1 while an emergency stop holds the vehicle (safety keeps flight authority until
    /// every engager has released it or an operator/safety `ClearEmergency`).
    pub emergency: u8,
    /// `CLOCK_MONOTONIC` ns of the last flight-authority change.
    pub flight_since_ns: u64,
    /// `CLOCK_MONOTONIC` ns of the last payload-authority change.
    pub payload_since_ns: u64,
    /// The sources whose emergency stop is in force: bit `1 << source.to_wire()`.
    pub emergency_sources: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: [u8; 7],
}
crate::assert_layout!(AuthorityState, size = 56, align = 8);

impl Default for AuthorityState {
    fn default() -> Self {
        AuthorityState {
            header: SampleHeader::default(),
            vehicle_id: 0,
            flight_holder: NO_HOLDER,
            flight_previous: NO_HOLDER,
            flight_change: AuthorityChange::None.to_wire(),
            payload_holder: NO_HOLDER,
            payload_previous: NO_HOLDER,
            payload_change: AuthorityChange::None.to_wire(),
            emergency: 0,
            flight_since_ns: 0,
            payload_since_ns: 0,
            emergency_sources: 0,
            reserved: [0; 7],
        }
    }
}

impl AuthorityState {
    pub fn flight(&self) -> Option<CommandSource> {
        CommandSource::try_from(self.flight_holder).ok()
    }
    pub fn payload(&self) -> Option<CommandSource> {
        CommandSource::try_from(self.payload_holder).ok()
    }
    /// Whether `source` has an emergency stop in force.
    pub fn emergency_by(&self, source: CommandSource) -> bool {
        self.emergency_sources & (1 << source.to_wire()) != 0
    }
}

wire_enum! {
    /// Something the arbiter did on its own.
    pub enum ArbiterEventKind: u8 {
        /// A setpoint stream stopped or went stale: the arbiter braked to a hover.
        StaleBrake = 1 => "stale_brake",
        /// A velocity setpoint was limited to stop before the geofence.
        GeofenceLimited = 2 => "geofence_limited",
        /// A position target outside the geofence was refused.
        GeofenceRefused = 3 => "geofence_refused",
        /// Emergency stop: braked, safety holds authority.
        EmergencyStop = 4 => "emergency_stop",
        /// The autopilot link went down: commands are refused until it is back.
        LinkLost = 5 => "link_lost",
        /// The autopilot link is back (nothing old is re-sent).
        LinkRestored = 6 => "link_restored",
        /// Authority changed hands (see [`AuthorityState`]).
        AuthorityChanged = 7 => "authority_changed",
        /// A new geofence was accepted.
        GeofenceUpdated = 8 => "geofence_updated",
        /// A geofence sample was refused (invalid polygon or numbers).
        GeofenceInvalid = 9 => "geofence_invalid",
        /// One engager withdrew its emergency stop; others may still hold it
        /// (`AuthorityState::emergency_sources`).
        EmergencyReleased = 10 => "emergency_released",
        /// The emergency stop ended: its last engager released it, or an operator or
        /// safety `ClearEmergency` cleared it (the detail names who).
        EmergencyCleared = 11 => "emergency_cleared",
        /// A command was refused because the autopilot flies its own failsafe.
        FailsafeHeld = 12 => "failsafe_held",
    }
}

/// One thing the arbiter did by itself, for gateways (to tell their users) and logs.
///
/// Topic: [`crate::topics::vehicle_arbiter_events`].
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[type_name("skymesh.ArbiterEvent.v2")]
#[repr(C)]
pub struct ArbiterEvent {
    pub header: SampleHeader,
    pub vehicle_id: u8,
    /// [`ArbiterEventKind`] as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::ArbiterEventKind>")
    )]
    pub kind: u8,
    /// The [`CommandSource`] concerned, or [`NO_HOLDER`].
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CommandSource>")
    )]
    pub source: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: u8,
    /// For geofence decisions: the [`GeofenceSet::request_id`] decided (0 = none), so
    /// the gateway that asked answers its client from the arbiter's decision.
    pub request_id: u32,
    pub detail: FixedStr<56>,
}
crate::assert_layout!(ArbiterEvent, size = 88, align = 8);

impl ArbiterEvent {
    pub fn event_kind(&self) -> Option<ArbiterEventKind> {
        ArbiterEventKind::try_from(self.kind).ok()
    }
}

/// Maximum polygons in one [`GeofenceSet`].
pub const MAX_FENCE_POLYGONS: usize = 8;
/// Maximum vertices of one polygon.
pub const MAX_FENCE_VERTICES: usize = 32;

wire_enum! {
    /// Whether a polygon is the allowed area or a forbidden one.
    pub enum FenceKind: u8 {
        KeepIn = 0 => "keep_in",
        KeepOut = 1 => "keep_out",
    }
}

/// One fence polygon, vertices in order (either winding), implicitly closed.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[repr(C)]
pub struct FencePolygon {
    /// [`FenceKind`] as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::FenceKind>")
    )]
    pub kind: u8,
    /// Valid entries of `vertices` (3..=MAX_FENCE_VERTICES).
    pub vertex_count: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: [u8; 6],
    /// Latitude, longitude in degrees.
    pub vertices: [[f64; 2]; MAX_FENCE_VERTICES],
}
crate::assert_layout!(FencePolygon, size = 8 + 16 * MAX_FENCE_VERTICES, align = 8);

impl Default for FencePolygon {
    fn default() -> Self {
        FencePolygon {
            kind: 0,
            vertex_count: 0,
            reserved: [0; 6],
            vertices: [[0.0; 2]; MAX_FENCE_VERTICES],
        }
    }
}

/// One source's geofence for one vehicle. The arbiter keeps one fence per source and
/// enforces all of them at once (inside every keep-in, outside every keep-out, the
/// lowest ceiling, the highest floor). A new sample from a source replaces that
/// source's fence entirely; `enabled = 0` clears the fence of `target_source`
/// ([`NO_HOLDER`]: the sender's own; another source's only from safety or operator).
/// The arbiter answers each sample with a `GeofenceUpdated` or `GeofenceInvalid`
/// event carrying `request_id`. Inside means: inside at least one keep-in polygon (if
/// any are given), outside every keep-out polygon, and between floor and ceiling.
///
/// Topic: [`crate::topics::vehicle_geofence`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[type_name("skymesh.GeofenceSet.v2")]
#[repr(C)]
pub struct GeofenceSet {
    pub header: SampleHeader,
    pub vehicle_id: u8,
    /// 0 = no geofence (clears any previous one).
    pub enabled: u8,
    /// Valid entries of `polygons`.
    pub polygon_count: u8,
    /// [`CommandSource`] that set it: the fence belongs to this source.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CommandSource>")
    )]
    pub source: u8,
    /// Chosen by the sender, echoed in the arbiter's decision event.
    pub request_id: u32,
    /// Altitude ceiling above home, m (`f32::INFINITY`-free: use a large number for none).
    pub ceiling_m: f32,
    /// Altitude floor above home, m (usually 0 or below).
    pub floor_m: f32,
    /// For `enabled = 0`: whose fence to clear ([`NO_HOLDER`] = the sender's own).
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CommandSource>")
    )]
    pub target_source: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: [u8; 7],
    pub polygons: [FencePolygon; MAX_FENCE_POLYGONS],
}
crate::assert_layout!(
    GeofenceSet,
    size = 48 + (8 + 16 * MAX_FENCE_VERTICES) * MAX_FENCE_POLYGONS,
    align = 8
);

impl Default for GeofenceSet {
    fn default() -> Self {
        GeofenceSet {
            header: SampleHeader::default(),
            vehicle_id: 0,
            enabled: 0,
            polygon_count: 0,
            source: NO_HOLDER,
            request_id: 0,
            ceiling_m: 120.0,
            floor_m: -10.0,
            target_source: NO_HOLDER,
            reserved: [0; 7],
            polygons: [FencePolygon::default(); MAX_FENCE_POLYGONS],
        }
    }
}

/// Why a [`GeofenceSet`] cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FenceError {
    #[error("polygon_count {0} exceeds {MAX_FENCE_POLYGONS}")]
    TooManyPolygons(u8),
    #[error("polygon {index}: {count} vertices, need 3..={MAX_FENCE_VERTICES}")]
    BadVertexCount { index: usize, count: u8 },
    #[error("polygon {index}: unknown kind {kind}")]
    BadKind { index: usize, kind: u8 },
    #[error("polygon {index} vertex {vertex}: not a finite lat/lon in range")]
    BadVertex { index: usize, vertex: usize },
    #[error("ceiling {ceiling} / floor {floor}: must be finite with floor < ceiling")]
    BadAltitude { ceiling: f32, floor: f32 },
}

/// One validated polygon: its kind and its vertices (lat, lon in degrees).
pub type FenceRing<'a> = (FenceKind, &'a [[f64; 2]]);

impl GeofenceSet {
    /// The valid polygons as (kind, vertices), after checking every number.
    pub fn polygons(&self) -> Result<Vec<FenceRing<'_>>, FenceError> {
        if usize::from(self.polygon_count) > MAX_FENCE_POLYGONS {
            return Err(FenceError::TooManyPolygons(self.polygon_count));
        }
        if !self.ceiling_m.is_finite()
            || !self.floor_m.is_finite()
            || self.floor_m >= self.ceiling_m
        {
            return Err(FenceError::BadAltitude {
                ceiling: self.ceiling_m,
                floor: self.floor_m,
            });
        }
        let mut out = Vec::with_capacity(self.polygon_count.into());
        for (index, p) in self.polygons[..usize::from(self.polygon_count)]
            .iter()
            .enumerate()
        {
            let kind = FenceKind::try_from(p.kind).map_err(|_| FenceError::BadKind {
                index,
                kind: p.kind,
            })?;
            let n = usize::from(p.vertex_count);
            if !(3..=MAX_FENCE_VERTICES).contains(&n) {
                return Err(FenceError::BadVertexCount {
                    index,
                    count: p.vertex_count,
                });
            }
            for (vertex, [lat, lon]) in p.vertices[..n].iter().enumerate() {
                let ok =
                    lat.is_finite() && lon.is_finite() && lat.abs() <= 90.0 && lon.abs() <= 180.0;
                if !ok {
                    return Err(FenceError::BadVertex { index, vertex });
                }
            }
            out.push((kind, &p.vertices[..n]));
        }
        Ok(out)
    }

    /// Adds a polygon; `false` if full or the vertex count is out of range.
    pub fn push_polygon(&mut self, kind: FenceKind, vertices: &[[f64; 2]]) -> bool {
        let i = usize::from(self.polygon_count);
        if i >= MAX_FENCE_POLYGONS || !(3..=MAX_FENCE_VERTICES).contains(&vertices.len()) {
            return false;
        }
        let p = &mut self.polygons[i];
        p.kind = kind.to_wire();
        p.vertex_count = vertices.len() as u8;
        p.vertices[..vertices.len()].copy_from_slice(vertices);
        self.polygon_count += 1;
        true
    }
}

crate::impl_sample!(AuthorityState, ArbiterEvent, GeofenceSet);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fence_validation_refuses_bad_numbers() {
        let mut g = GeofenceSet {
            enabled: 1,
            ..Default::default()
        };
        assert!(g.push_polygon(FenceKind::KeepIn, &[[0.0, 0.0], [0.0, 1.0], [1.0, 1.0]]));
        assert_eq!(g.polygons().unwrap().len(), 1);
        g.polygons[0].vertices[1][0] = f64::NAN;
        assert_eq!(
            g.polygons(),
            Err(FenceError::BadVertex {
                index: 0,
                vertex: 1
            })
        );
        g.polygons[0].vertices[1][0] = 0.0;
        g.polygons[0].kind = 9;
        assert!(matches!(g.polygons(), Err(FenceError::BadKind { .. })));
        g.polygons[0].kind = 0;
        g.ceiling_m = f32::INFINITY;
        assert!(matches!(g.polygons(), Err(FenceError::BadAltitude { .. })));
        g.ceiling_m = 50.0;
        g.polygon_count = 200;
        assert_eq!(g.polygons(), Err(FenceError::TooManyPolygons(200)));
        assert!(!GeofenceSet::default().push_polygon(FenceKind::KeepOut, &[[0.0, 0.0]]));
    }

    #[test]
    fn priorities_follow_the_safety_order() {
        use CommandSource::*;
        let order = [
            Safety, ManualRc, Operator, DjiDrc, ShotEngine, SwarmQueue, Imc, Vision,
        ];
        for w in order.windows(2) {
            assert!(
                w[0].priority() > w[1].priority(),
                "{:?} vs {:?}",
                w[0],
                w[1]
            );
        }
    }
}
