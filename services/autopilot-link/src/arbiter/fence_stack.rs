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

use skymesh_ipc_types::{ArbiterEventKind, CommandSource, GeofenceSet, NO_HOLDER};

use super::geofence::Fence;
use super::{Arbiter, Effect};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arbiter::geofence::LocalFrame;
    use crate::arbiter::tests::{flying, refusal, sample, settings, S};
    use skymesh_ipc_types::{
        AckResult, Command,
        CommandSource::{Operator, Safety, ShotEngine, SwarmQueue, Vision},
        FenceKind, RefusalReason,
    };

    const HOME: (f64, f64) = (-35.363261, 149.165230);

    /// Latitude/longitude of a point `north`/`east` metres from home.
    fn ll(north: f64, east: f64) -> [f64; 2] {
        let unit = LocalFrame::new(HOME.0, HOME.1).to_local(HOME.0 + 1e-3, HOME.1 + 1e-3);
        [
            HOME.0 + north / unit.x * 1e-3,
            HOME.1 + east / unit.y * 1e-3,
        ]
    }

    /// `source`'s keep-in rectangle, north `n0..n1`, east `e0..e1` metres.
    fn keep_in(source: CommandSource, (n0, n1): (f64, f64), (e0, e1): (f64, f64)) -> GeofenceSet {
        let mut set = GeofenceSet {
            vehicle_id: 1,
            enabled: 1,
            source: source.to_wire(),
            request_id: 40 + u32::from(source.to_wire()),
            ceiling_m: 60.0,
            floor_m: -5.0,
            ..Default::default()
        };
        assert!(set.push_polygon(
            FenceKind::KeepIn,
            &[ll(n0, e0), ll(n1, e0), ll(n1, e1), ll(n0, e1)]
        ));
        set
    }

    fn clear(source: CommandSource, target: Option<CommandSource>, request_id: u32) -> GeofenceSet {
        GeofenceSet {
            vehicle_id: 1,
            enabled: 0,
            source: source.to_wire(),
            target_source: target.map_or(NO_HOLDER, CommandSource::to_wire),
            request_id,
            ..Default::default()
        }
    }

    /// The one decision event: (kind, request id, detail).
    fn decision(fx: &[Effect]) -> (ArbiterEventKind, u32, &str) {
        match fx {
            [Effect::Fence {
                kind,
                request_id,
                detail,
                ..
            }] => (*kind, *request_id, detail.as_str()),
            other => panic!("expected one fence decision, got {other:?}"),
        }
    }

    fn goto(north: f64, east: f64) -> Command {
        let [lat_deg, lon_deg] = ll(north, east);
        Command::GoTo {
            lat_deg,
            lon_deg,
            alt_rel_m: 10.0,
            yaw_deg: None,
            speed_mps: Some(3.0),
        }
    }

    #[test]
    fn each_source_keeps_its_own_fence_and_clears_only_its_own() {
        let mut a = Arbiter::new(settings());
        // GroundControl (the swarm queue) sets a 100 m box, the Solo app (the shot
        // engine) a fence that reaches further east but not as far north.
        let fx = a.set_geofence(&keep_in(SwarmQueue, (-50.0, 50.0), (-50.0, 50.0)), 1);
        assert_eq!(decision(&fx).0, ArbiterEventKind::GeofenceUpdated);
        assert_eq!(decision(&fx).1, 44, "request id echoed");
        let fx = a.set_geofence(&keep_in(ShotEngine, (-30.0, 30.0), (-30.0, 200.0)), 1);
        assert_eq!(decision(&fx).0, ArbiterEventKind::GeofenceUpdated);
        assert_eq!(a.fence().len(), 2);
        assert!(a.fence().contains(ll(20.0, 20.0)[0], ll(20.0, 20.0)[1]));
        let [lat, lon] = ll(40.0, 0.0);
        assert!(!a.fence().contains(lat, lon), "outside the Solo fence");
        let [lat, lon] = ll(0.0, 80.0);
        assert!(
            !a.fence().contains(lat, lon),
            "outside the GroundControl box"
        );
        let v = flying(0.0, 0.0, [0.0; 3]);
        let d = a.decide(S, &sample(Operator, goto(0.0, 80.0), S), &v);
        assert_eq!(refusal(&d).0, RefusalReason::Geofence, "the box holds");
        let d = a.decide(S, &sample(Operator, goto(40.0, 0.0), S), &v);
        assert_eq!(
            refusal(&d).0,
            RefusalReason::Geofence,
            "the Solo fence holds"
        );

        // The shot engine may not clear the swarm queue's box...
        let fx = a.set_geofence(&clear(ShotEngine, Some(SwarmQueue), 7), 1);
        assert_eq!(
            decision(&fx),
            (
                ArbiterEventKind::GeofenceInvalid,
                7,
                "shot_engine may not clear swarm_queue's fence"
            )
        );
        assert_eq!(a.fence().len(), 2);
        // ... nor set a fence in its name.
        let mut theirs = keep_in(ShotEngine, (-5.0, 5.0), (-5.0, 5.0));
        theirs.target_source = SwarmQueue.to_wire();
        let fx = a.set_geofence(&theirs, 1);
        assert_eq!(decision(&fx).0, ArbiterEventKind::GeofenceInvalid);
        // The app disconnects: its gateway clears the Solo fence; the box still holds.
        let fx = a.set_geofence(&clear(ShotEngine, None, 8), 1);
        assert_eq!(
            decision(&fx),
            (
                ArbiterEventKind::GeofenceUpdated,
                8,
                "shot_engine cleared its fence; 1 left"
            )
        );
        assert!(a.fence().get(ShotEngine).is_none());
        assert!(a.fence().get(SwarmQueue).is_some());
        let d = a.decide(2 * S, &sample(Operator, goto(40.0, 0.0), 2 * S), &v);
        assert_ne!(d.result(), AckResult::Refused, "inside the box now: {d:?}");
        let d = a.decide(2 * S, &sample(Operator, goto(0.0, 80.0), 2 * S), &v);
        assert_eq!(
            refusal(&d).0,
            RefusalReason::Geofence,
            "the box still holds"
        );
        // A second clear of a fence that is gone: accepted, nothing changes.
        let fx = a.set_geofence(&clear(ShotEngine, None, 9), 1);
        assert_eq!(decision(&fx).0, ArbiterEventKind::GeofenceUpdated);
        assert_eq!(a.fence().len(), 1);
    }

    #[test]
    fn safety_and_operator_may_clear_any_fence_and_are_named() {
        let mut a = Arbiter::new(settings());
        a.set_geofence(&keep_in(SwarmQueue, (-50.0, 50.0), (-50.0, 50.0)), 1);
        a.set_geofence(&keep_in(Vision, (-40.0, 40.0), (-40.0, 40.0)), 1);
        let fx = a.set_geofence(&clear(Operator, Some(SwarmQueue), 3), 1);
        assert_eq!(
            decision(&fx),
            (
                ArbiterEventKind::GeofenceUpdated,
                3,
                "operator cleared swarm_queue's fence; 1 left"
            )
        );
        let fx = a.set_geofence(&clear(Safety, Some(Vision), 4), 1);
        assert_eq!(decision(&fx).2, "safety cleared vision's fence; 0 left");
        assert!(a.fence().is_empty());
        assert_eq!(a.fence().ceiling_m(), None);
    }

    #[test]
    fn the_fences_combine_to_the_strictest_altitudes_and_restore_from_their_samples() {
        let mut a = Arbiter::new(settings());
        let mut box_set = keep_in(SwarmQueue, (-50.0, 50.0), (-50.0, 50.0));
        box_set.ceiling_m = 40.0;
        box_set.floor_m = -10.0;
        let mut solo = keep_in(ShotEngine, (-30.0, 30.0), (-30.0, 200.0));
        solo.ceiling_m = 80.0;
        solo.floor_m = 2.0;
        a.set_geofence(&solo, 1);
        a.set_geofence(&box_set, 1);
        assert_eq!(a.fence().ceiling_m(), Some(40.0));
        assert_eq!(a.fence().floor_m(), Some(2.0));
        assert!(a.fence().altitude_ok(20.0));
        assert!(!a.fence().altitude_ok(45.0) && !a.fence().altitude_ok(1.0));
        // The state file keeps the samples; set again, they give the same stack.
        let sets = a.fence_sets();
        assert_eq!(sets, [solo, box_set], "ordered by source");
        let mut b = Arbiter::new(settings());
        for set in &sets {
            assert_eq!(
                decision(&b.set_geofence(set, 1)).0,
                ArbiterEventKind::GeofenceUpdated
            );
        }
        assert_eq!(b.fence(), a.fence());
        // A source's new fence replaces only its own.
        a.set_geofence(&keep_in(ShotEngine, (-20.0, 20.0), (-20.0, 20.0)), 1);
        assert_eq!(a.fence().len(), 2);
        assert_eq!(a.fence().floor_m(), Some(-5.0));
    }

    #[test]
    fn invalid_samples_change_nothing_and_say_why() {
        let mut a = Arbiter::new(settings());
        a.set_geofence(&keep_in(SwarmQueue, (-50.0, 50.0), (-50.0, 50.0)), 1);
        let mut bad = keep_in(SwarmQueue, (-10.0, 10.0), (-10.0, 10.0));
        bad.polygons[0].vertices[1][0] = f64::NAN;
        let fx = a.set_geofence(&bad, 1);
        assert_eq!(decision(&fx).0, ArbiterEventKind::GeofenceInvalid);
        assert_eq!(decision(&fx).1, 44);
        let fx = a.set_geofence(&keep_in(SwarmQueue, (-1.0, 1.0), (-1.0, 1.0)), 2);
        assert_eq!(
            decision(&fx),
            (ArbiterEventKind::GeofenceInvalid, 44, "fence for vehicle 1")
        );
        let mut unknown = keep_in(SwarmQueue, (-1.0, 1.0), (-1.0, 1.0));
        unknown.source = 99;
        assert_eq!(
            decision(&a.set_geofence(&unknown, 1)).2,
            "unknown source 99"
        );
        let mut target = clear(Operator, None, 5);
        target.target_source = 77;
        assert_eq!(
            decision(&a.set_geofence(&target, 1)).2,
            "unknown target source 77"
        );
        let fx = a.fence_sets();
        assert_eq!(fx.len(), 1);
        assert_eq!(fx[0], keep_in(SwarmQueue, (-50.0, 50.0), (-50.0, 50.0)));
    }
}
