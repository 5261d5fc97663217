//! Record mode of the multipoint cable cam: keypoints recorded at the vehicle
//! (RECORD_POSITION, A, B) or loaded by the app (SPLINE_POINT), each request
//! answered with exactly one SPLINE_POINT (see the parent module's table).

use skymesh_ipc_types::shot_api::{ShotEvent, SplinePoint};
use skymesh_ipc_types::Button;

use super::{Active, Engine, MultipointShot, Out, ShotKind};
use crate::shots::spline::MAX_KEYPOINTS;
use crate::shots::{distance_m, GeoPoint, Keypoint};

/// SOLO_SPLINE_POINT statuses (the spec's error codes).
pub mod status {
    pub const OK: i16 = 0;
    /// Tried to set a keypoint in play mode.
    pub const MODE: i16 = -1;
    /// Too close to the keypoint before or after.
    pub const TOO_CLOSE: i16 = -2;
    /// A keypoint with this index exists.
    pub const DUPLICATE_INDEX: i16 = -3;
    /// Anything else.
    pub const OTHER: i16 = -4;
}

/// The only SOLO_SPLINE_POINT layout version the reference loads.
pub(super) const POINT_VERSION: i16 = 0;

/// Whether a recorded or loaded keypoint may come from the app in this state.
enum Slot<'a> {
    Record(&'a mut MultipointShot),
    Playing,
    NotInShot,
}

/// The multipoint shot's slot for a keypoint (borrows only the active shot).
fn slot(active: &mut Option<Active>) -> Slot<'_> {
    match active.as_mut() {
        Some(Active {
            kind: ShotKind::Multipoint(m),
            ..
        }) if m.play.is_some() => Slot::Playing,
        Some(Active {
            kind: ShotKind::Multipoint(m),
            ..
        }) => Slot::Record(m),
        _ => Slot::NotInShot,
    }
}

impl Engine {
    /// Home altitude above MSL now, metres (absAltRef of a new path).
    fn home_alt_msl(&self) -> f32 {
        match (&self.inputs.status, &self.inputs.state) {
            (Some(s), _) if s.home_valid != 0 && s.home_alt_msl_m.is_finite() => s.home_alt_msl_m,
            (_, Some((st, _))) if (st.alt_msl_m - st.alt_rel_m).is_finite() => {
                st.alt_msl_m - st.alt_rel_m
            }
            _ => 0.0,
        }
    }

    /// RECORD_POSITION from the app (`from_app`: one SPLINE_POINT reply whatever
    /// happens), or A/B in record mode. True when a keypoint was stored.
    pub(crate) fn multipoint_record(&mut self, from_app: bool, now_ns: u64) -> bool {
        let view = self.inputs.view(now_ns);
        let abs_alt = self.home_alt_msl();
        let spacing = self.settings.keypoint_min_spacing_m;
        let reply = |out: &mut Out, p: SplinePoint| {
            if from_app {
                out.app(ShotEvent::SplinePoint(p));
            }
        };
        let failed = |index: i32, status: i16| SplinePoint {
            version: POINT_VERSION,
            abs_alt_ref_m: abs_alt,
            index,
            lat_deg: view.map_or(0.0, |v| v.position.lat_deg),
            lon_deg: view.map_or(0.0, |v| v.position.lon_deg),
            alt_m: view.map_or(0.0, |v| v.position.alt_rel_m),
            pitch_deg: view.map_or(0.0, |v| v.camera_pitch_deg),
            yaw_deg: view.map_or(0.0, |v| v.heading_deg),
            u_position: 0.0,
            status,
        };
        let m = match slot(&mut self.active) {
            Slot::Record(m) => m,
            Slot::Playing => {
                tracing::info!("multipoint: cannot record a keypoint in play mode");
                reply(&mut self.out, failed(-1, status::MODE));
                return false;
            }
            Slot::NotInShot => return false,
        };
        let index = m.next_index();
        let Some(v) = view else {
            tracing::warn!("multipoint: no vehicle position; keypoint not recorded");
            reply(&mut self.out, failed(index, status::OTHER));
            if !from_app {
                self.out
                    .error("multipoint: no vehicle position; the keypoint was not recorded");
            }
            return false;
        };
        let k = Keypoint {
            position: v.position,
            pitch_deg: v.camera_pitch_deg,
            yaw_deg: v.heading_deg,
        };
        // On top of the last keypoint: it replaces it (coalesced, same index).
        let last = m.keypoints.last_key_value().map(|(i, p)| (*i, p.position));
        let index = match last {
            Some((i, p)) if distance_m(&p, &k.position) < spacing => i,
            _ if m.keypoints.len() >= MAX_KEYPOINTS => {
                tracing::warn!(max = MAX_KEYPOINTS, "multipoint: the path is full");
                reply(&mut self.out, failed(index, status::OTHER));
                return false;
            }
            _ => index,
        };
        if m.keypoints.is_empty() {
            m.abs_alt_ref_m = Some(abs_alt);
        }
        m.keypoints.insert(index, k);
        let p = m.point(index, &k, 0.0, status::OK);
        tracing::info!(
            index,
            lat = k.position.lat_deg,
            lon = k.position.lon_deg,
            alt = k.position.alt_rel_m,
            "multipoint: keypoint recorded"
        );
        // A recorded keypoint is always sent: that is how the app learns of it.
        self.out.app(ShotEvent::SplinePoint(p));
        true
    }

    /// SOLO_SPLINE_POINT from the app: validate, store, one reply.
    pub(crate) fn spline_point(&mut self, p: SplinePoint) {
        let spacing = self.settings.keypoint_min_spacing_m;
        let reply = |status: i16| SplinePoint { status, ..p };
        let m = match slot(&mut self.active) {
            Slot::Record(m) => m,
            Slot::Playing => {
                tracing::info!(index = p.index, "multipoint: keypoint refused in play mode");
                self.out.app(ShotEvent::SplinePoint(reply(status::MODE)));
                return;
            }
            Slot::NotInShot => {
                tracing::info!(
                    index = p.index,
                    "SPLINE_POINT outside the multipoint cable cam refused"
                );
                self.out.app(ShotEvent::SplinePoint(reply(status::OTHER)));
                return;
            }
        };
        let k = Keypoint {
            position: GeoPoint {
                lat_deg: p.lat_deg,
                lon_deg: p.lon_deg,
                alt_rel_m: p.alt_m,
            },
            pitch_deg: p.pitch_deg,
            yaw_deg: p.yaw_deg,
        };
        let near = |i: i32| {
            m.keypoints.get(&i).is_some_and(|n| {
                // NaN (no distance) counts as too close.
                let d = distance_m(&n.position, &k.position);
                d.is_nan() || d < spacing
            })
        };
        let status =
            if p.version != POINT_VERSION || p.index < 0 || p.index as usize >= MAX_KEYPOINTS {
                status::OTHER
            } else if m.keypoints.contains_key(&p.index) {
                status::DUPLICATE_INDEX
            } else if near(p.index - 1) || near(p.index + 1) {
                status::TOO_CLOSE
            } else {
                status::OK
            };
        if status != status::OK {
            tracing::info!(index = p.index, status, "multipoint: app keypoint refused");
            self.out.app(ShotEvent::SplinePoint(reply(status)));
            return;
        }
        if m.keypoints.is_empty() {
            m.abs_alt_ref_m = Some(p.abs_alt_ref_m);
        }
        m.keypoints.insert(p.index, k);
        let stored = m.point(p.index, &k, 0.0, status::OK);
        tracing::info!(index = p.index, "multipoint: app keypoint loaded");
        self.out.app(ShotEvent::SplinePoint(stored));
    }

    /// A or B in the multipoint cable cam (record mode only, as on the Solo).
    pub(crate) fn multipoint_button(&mut self, button: Button, now_ns: u64) {
        if !matches!(slot(&mut self.active), Slot::Record(_)) {
            tracing::info!(%button, "multipoint: buttons do nothing in play mode");
            return;
        }
        match button {
            Button::A => {
                self.multipoint_record(false, now_ns);
            }
            Button::B => {
                self.multipoint_record(false, now_ns);
                self.spline_play(true);
            }
            _ => {}
        }
    }
}
