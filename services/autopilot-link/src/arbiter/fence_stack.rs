//! One geofence per source, all enforced at once.
//!
//! Every [`CommandSource`] may keep one fence ([`GeofenceSet`]); a new sample from a
//! source replaces that source's fence only, so a GroundControl keep-in box is not
//! lost when a Solo app sets or clears its own. The vehicle must be inside every
//! source's fence: inside every source's keep-in (when that source gave any), outside
//! every keep-out, under the lowest ceiling and above the highest floor.
//!
//! `enabled = 0` clears the fence of `target_source` ([`NO_HOLDER`]: the sender's
//! own). Clearing another source's fence is for the safety and operator sources only,
//! and the event detail names who cleared whose. Every sample is answered by one
//! [`Effect::Fence`] (`GeofenceUpdated` or `GeofenceInvalid`) echoing its
//! `request_id`, from which the gateway that asked answers its client.
//!
//! The velocity limit and the path check over the stack (stopping trajectories) are
//! in [`super::fence_stopping`].

use skymesh_ipc_types::{ArbiterEventKind, CommandSource, GeofenceSet, NO_HOLDER};

use super::geofence::Fence;
use super::{Arbiter, Effect};

pub use super::fence_stopping::MODEL_SLACK_M;

/// One source's fence: the compiled geometry and the sample it came from (kept for
/// the state file: restoring is [`Arbiter::set_geofence`] with each).
#[derive(Debug, Clone, PartialEq)]
struct Entry {
    source: CommandSource,
    set: Box<GeofenceSet>,
    fence: Fence,
}

/// The fences in force, at most one per source, ordered by source.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FenceStack {
    entries: Vec<Entry>,
}

impl FenceStack {
    /// No fence in force.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// How many sources have a fence.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// The fences in force with their owners.
    pub fn iter(&self) -> impl Iterator<Item = (CommandSource, &Fence)> + '_ {
        self.entries.iter().map(|e| (e.source, &e.fence))
    }

    /// The compiled fences, without owners.
    pub fn fences(&self) -> impl Iterator<Item = &Fence> + '_ {
        self.entries.iter().map(|e| &e.fence)
    }

    /// `source`'s fence, if it has one.
    pub fn get(&self, source: CommandSource) -> Option<&Fence> {
        self.entries
            .iter()
            .find(|e| e.source == source)
            .map(|e| &e.fence)
    }

    /// The samples the fences came from, ordered by source.
    pub fn sets(&self) -> Vec<GeofenceSet> {
        self.entries.iter().map(|e| *e.set).collect()
    }

    /// Horizontally inside every source's fence (true when there is none).
    pub fn contains(&self, lat_deg: f64, lon_deg: f64) -> bool {
        self.fences()
            .all(|f| f.contains(f.frame.to_local(lat_deg, lon_deg)))
    }

    /// Between the highest floor and the lowest ceiling.
    pub fn altitude_ok(&self, alt_rel_m: f32) -> bool {
        self.fences().all(|f| f.altitude_ok(alt_rel_m))
    }

    /// The lowest ceiling, `None` without a fence.
    pub fn ceiling_m(&self) -> Option<f32> {
        self.fences().map(|f| f.ceiling_m).reduce(f32::min)
    }

    /// The highest floor, `None` without a fence.
    pub fn floor_m(&self) -> Option<f32> {
        self.fences().map(|f| f.floor_m).reduce(f32::max)
    }

    /// Sets `source`'s fence, replacing its previous one.
    fn insert(&mut self, source: CommandSource, set: &GeofenceSet, fence: Fence) {
        let entry = Entry {
            source,
            set: Box::new(*set),
            fence,
        };
        match self
            .entries
            .binary_search_by_key(&source.to_wire(), |e| e.source.to_wire())
        {
            Ok(i) => self.entries[i] = entry,
            Err(i) => self.entries.insert(i, entry),
        }
    }

    /// Removes `source`'s fence; whether it had one.
    fn remove(&mut self, source: CommandSource) -> bool {
        let before = self.entries.len();
        self.entries.retain(|e| e.source != source);
        self.entries.len() != before
    }
}

/// Fences at most: one per source.
pub(super) const MAX_FENCES: usize = CommandSource::ALL.len();

/// May clear another source's fence.
fn may_clear_others(source: CommandSource) -> bool {
    matches!(source, CommandSource::Safety | CommandSource::Operator)
}

impl Arbiter {
    /// The fences in force.
    pub fn fence(&self) -> &FenceStack {
        &self.fence
    }

    /// The samples of the fences in force, for the state file; restoring them is
    /// [`Arbiter::set_geofence`] with each.
    pub fn fence_sets(&self) -> Vec<GeofenceSet> {
        self.fence.sets()
    }

    /// A `GeofenceSet` arrived: set or clear one source's fence (see the module doc).
    /// An invalid sample (bad numbers, another vehicle, an unknown source, a source
    /// clearing another's fence without the right to) changes nothing. Returns exactly
    /// one [`Effect::Fence`] with the sample's `request_id`.
    pub fn set_geofence(&mut self, set: &GeofenceSet, vehicle_id: u8) -> Vec<Effect> {
        let sender = CommandSource::try_from(set.source).ok();
        let (kind, detail) = match self.fence_decision(set, sender, vehicle_id) {
            Ok(detail) => (ArbiterEventKind::GeofenceUpdated, detail),
            Err(detail) => (ArbiterEventKind::GeofenceInvalid, detail),
        };
        vec![Effect::Fence {
            kind,
            source: sender,
            request_id: set.request_id,
            detail,
        }]
    }

    fn fence_decision(
        &mut self,
        set: &GeofenceSet,
        sender: Option<CommandSource>,
        vehicle_id: u8,
    ) -> Result<String, String> {
        if set.vehicle_id != vehicle_id {
            return Err(format!("fence for vehicle {}", set.vehicle_id));
        }
        let Some(source) = sender else {
            return Err(format!("unknown source {}", set.source));
        };
        let target = if set.target_source == NO_HOLDER {
            source
        } else {
            CommandSource::try_from(set.target_source)
                .map_err(|_| format!("unknown target source {}", set.target_source))?
        };
        if set.enabled == 0 {
            if target != source && !may_clear_others(source) {
                // Only safety and operator may: the detail says whose it is.
                return Err(format!("{source} may not clear {target}'s fence"));
            }
            let had = self.fence.remove(target);
            if self.fence.is_empty() {
                self.fence_limiting = false;
            }
            let left = self.fence.len();
            return Ok(match (had, target == source) {
                (true, true) => format!("{source} cleared its fence; {left} left"),
                (true, false) => format!("{source} cleared {target}'s fence; {left} left"),
                (false, _) => format!("{target} had no fence; {left} in force"),
            });
        }
        if target != source {
            return Err(format!("{source} may not set {target}'s fence"));
        }
        match Fence::compile(set) {
            Err(e) => Err(e.to_string()),
            Ok(None) => Err("disabled fence with polygons".to_string()),
            Ok(Some(fence)) => {
                let detail = format!(
                    "{source}: {} polygons, {:.0}..{:.0} m",
                    fence.polygons.len(),
                    fence.floor_m,
                    fence.ceiling_m
                );
                self.fence.insert(source, set, fence);
                Ok(format!("{detail}; {} fences", self.fence.len()))
            }
        }
    }
}
