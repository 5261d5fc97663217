//! The Solo app's geofence on its way from the gateway to the shot engine.
//!
//! GEOFENCE_SET_DATA is JSON of up to 64 KiB and fits no [`crate::ShotRequestSample`]
//! (240 bytes of body), so solo-gateway decodes it and publishes the polygons as one
//! fixed-capacity [`AppGeofence`]: at most
//! [`MAX_APP_FENCE_POLYGONS`] polygons of at most [`MAX_APP_FENCE_VERTICES`]
//! vertices each (more cannot be carried: the gateway answers the app itself).
//! The gateway only translates; whether the polygons make a usable fence (three or
//! more vertices, as many sub-polygon vertices as polygon vertices, finite numbers)
//! is the shot engine's decision, and it answers the app with GEOFENCE_SET_ACK.

use iceoryx2::prelude::ZeroCopySend;

use crate::header::SampleHeader;

/// Polygons one [`AppGeofence`] carries (the arbiter's `MAX_FENCE_POLYGONS`).
pub const MAX_APP_FENCE_POLYGONS: usize = crate::arbiter::MAX_FENCE_POLYGONS;
/// Vertices of one polygon or sub-polygon (the arbiter's `MAX_FENCE_VERTICES`).
pub const MAX_APP_FENCE_VERTICES: usize = crate::arbiter::MAX_FENCE_VERTICES;

/// One polygon of the app's geofence and its sub-polygon, as the app sent them.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct AppFencePolygon {
    /// The app's `type`: 0 inclusive (keep in), 1 exclusive (keep out); any other
    /// value is carried as received and refused by the engine.
    pub kind: u8,
    /// Valid entries of `vertices` (0..=MAX_APP_FENCE_VERTICES).
    pub vertex_count: u8,
    /// Valid entries of `sub_vertices` (0..=MAX_APP_FENCE_VERTICES).
    pub sub_vertex_count: u8,
    pub reserved: [u8; 5],
    /// The polygon (`coord`): latitude, longitude in degrees, in the app's order.
    pub vertices: [[f64; 2]; MAX_APP_FENCE_VERTICES],
    /// The sub-polygon (`subCoord`): the inner warning line of a keep-in polygon,
    /// the outer one of a keep-out polygon; latitude, longitude in degrees.
    pub sub_vertices: [[f64; 2]; MAX_APP_FENCE_VERTICES],
}
crate::assert_layout!(
    AppFencePolygon,
    size = 8 + 2 * 16 * MAX_APP_FENCE_VERTICES,
    align = 8
);

impl Default for AppFencePolygon {
    fn default() -> Self {
        AppFencePolygon {
            kind: 0,
            vertex_count: 0,
            sub_vertex_count: 0,
            reserved: [0; 5],
            vertices: [[0.0; 2]; MAX_APP_FENCE_VERTICES],
            sub_vertices: [[0.0; 2]; MAX_APP_FENCE_VERTICES],
        }
    }
}

impl AppFencePolygon {
    /// The polygon's vertices in use (a forged count is clamped to the capacity).
    pub fn vertices(&self) -> &[[f64; 2]] {
        &self.vertices[..usize::from(self.vertex_count).min(MAX_APP_FENCE_VERTICES)]
    }

    /// The sub-polygon's vertices in use (a forged count is clamped to the capacity).
    pub fn sub_vertices(&self) -> &[[f64; 2]] {
        &self.sub_vertices[..usize::from(self.sub_vertex_count).min(MAX_APP_FENCE_VERTICES)]
    }
}

/// Why polygons cannot be carried by an [`AppGeofence`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum AppFenceTooLarge {
    #[error("{0} polygons; skymesh carries at most {MAX_APP_FENCE_POLYGONS}")]
    Polygons(usize),
    #[error(
        "polygon {index} has {count} vertices; skymesh carries at most {MAX_APP_FENCE_VERTICES}"
    )]
    Vertices { index: usize, count: usize },
}

/// The app's geofence (GEOFENCE_SET_DATA), translated by solo-gateway.
///
/// Topic: [`crate::topics::shot_app_geofence`] (gateway → shot engine; every
/// sample is one request the engine answers).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("skymesh.AppGeofence.v1")]
#[repr(C)]
pub struct AppGeofence {
    pub header: SampleHeader,
    /// The app connection it came from (as [`crate::ShotRequestSample::session`]).
    pub session: u32,
    /// Valid entries of `polygons` (0 = the app sent no polygon).
    pub polygon_count: u8,
    pub reserved: [u8; 3],
    pub polygons: [AppFencePolygon; MAX_APP_FENCE_POLYGONS],
}
crate::assert_layout!(
    AppGeofence,
    size = 24 + 8 + (8 + 2 * 16 * MAX_APP_FENCE_VERTICES) * MAX_APP_FENCE_POLYGONS,
    align = 8
);

impl Default for AppGeofence {
    fn default() -> Self {
        AppGeofence {
            header: SampleHeader::default(),
            session: 0,
            polygon_count: 0,
            reserved: [0; 3],
            polygons: [AppFencePolygon::default(); MAX_APP_FENCE_POLYGONS],
        }
    }
}

impl AppGeofence {
    /// Packs the app's polygons: `(kind, polygon, sub-polygon)` each, in order.
    /// Counts are not judged here beyond what fits (a 2-vertex polygon is carried
    /// for the engine to refuse).
    pub fn new<'a>(
        session: u32,
        polygons: impl ExactSizeIterator<Item = (u8, &'a [[f64; 2]], &'a [[f64; 2]])>,
    ) -> Result<AppGeofence, AppFenceTooLarge> {
        if polygons.len() > MAX_APP_FENCE_POLYGONS {
            return Err(AppFenceTooLarge::Polygons(polygons.len()));
        }
        let mut g = AppGeofence {
            session,
            ..AppGeofence::default()
        };
        for (index, (kind, coord, sub)) in polygons.enumerate() {
            for count in [coord.len(), sub.len()] {
                if count > MAX_APP_FENCE_VERTICES {
                    return Err(AppFenceTooLarge::Vertices { index, count });
                }
            }
            let p = &mut g.polygons[index];
            p.kind = kind;
            p.vertex_count = coord.len() as u8;
            p.sub_vertex_count = sub.len() as u8;
            p.vertices[..coord.len()].copy_from_slice(coord);
            p.sub_vertices[..sub.len()].copy_from_slice(sub);
            g.polygon_count = (index + 1) as u8;
        }
        Ok(g)
    }

    /// The polygons in use (a forged count is clamped to the capacity).
    pub fn polygons(&self) -> &[AppFencePolygon] {
        &self.polygons[..usize::from(self.polygon_count).min(MAX_APP_FENCE_POLYGONS)]
    }
}

crate::impl_sample!(AppGeofence);

#[cfg(test)]
mod tests {
    use super::*;

    const TRI: [[f64; 2]; 3] = [[0.0, 0.0], [0.0, 1.0], [1.0, 1.0]];

    #[test]
    fn polygons_are_packed_in_order() {
        let inner = [[0.1, 0.1], [0.1, 0.9], [0.9, 0.9]];
        let g = AppGeofence::new(
            4,
            [(0, &TRI[..], &inner[..]), (1, &TRI[..2], &inner[..])].into_iter(),
        )
        .unwrap();
        assert_eq!(g.session, 4);
        assert_eq!(g.polygons().len(), 2);
        assert_eq!(g.polygons()[0].vertices(), &TRI);
        assert_eq!(g.polygons()[0].sub_vertices(), &inner);
        assert_eq!(g.polygons()[1].kind, 1);
        // Carried as sent: the engine judges a 2-vertex polygon.
        assert_eq!(g.polygons()[1].vertices().len(), 2);
    }

    #[test]
    fn what_does_not_fit_is_refused() {
        let nine = vec![(0u8, &TRI[..], &TRI[..]); MAX_APP_FENCE_POLYGONS + 1];
        assert_eq!(
            AppGeofence::new(1, nine.into_iter()),
            Err(AppFenceTooLarge::Polygons(9))
        );
        let long = [[0.0; 2]; MAX_APP_FENCE_VERTICES + 1];
        assert_eq!(
            AppGeofence::new(1, [(0u8, &TRI[..], &long[..])].into_iter()),
            Err(AppFenceTooLarge::Vertices {
                index: 0,
                count: 33
            })
        );
    }

    #[test]
    fn forged_counts_are_clamped() {
        let mut g = AppGeofence {
            polygon_count: 200,
            ..AppGeofence::default()
        };
        g.polygons[0].vertex_count = 255;
        assert_eq!(g.polygons().len(), MAX_APP_FENCE_POLYGONS);
        assert_eq!(g.polygons()[0].vertices().len(), MAX_APP_FENCE_VERTICES);
    }
}
