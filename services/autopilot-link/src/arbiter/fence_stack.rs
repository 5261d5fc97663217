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

use super::geofence::{point_segment_dist2, stoppable, Envelope, Fence, Limit, Ne, MAX_FIX_AGE_S};
use super::{Arbiter, Effect, Kinematics};

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
const MAX_FENCES: usize = CommandSource::ALL.len();
/// Segments of one stopping-trajectory check (see [`FenceStack::limit_velocity`]).
const MAX_SEGMENTS: usize = 5 + 3 * MAX_CHORDS;
/// The transition from the current velocity to the command is followed in at most
/// this many chords...
const MAX_CHORDS: usize = 16;
/// ... each at most this long (s) while that cap allows.
const CHORD_S: f64 = 0.2;
/// Steps of the bisection for the largest allowed fraction of a command.
const BISECT_STEPS: u32 = 10;
/// Inward speed commanded when even a stop now would end within the margin, m/s.
const BACK_IN_MPS: f64 = 1.0;
/// Slack for rounding in "no closer than the start" comparisons, m.
const EPS_M: f64 = 1e-6;
/// Added to the margin when the vehicle is outside it: the trajectory models are
/// followed in chords and a vehicle between them may stray a few centimetres
/// further (the property test found 4 cm on a long, slightly turning change of
/// velocity); the margin itself is what the tests assert.
pub const MODEL_SLACK_M: f64 = 0.1;

/// A segment of a stopping trajectory, as offsets from the vehicle, m.
type Segment = (Ne, Ne);

/// The vehicle's position in each fence's own local frame, in fence order.
#[derive(Clone, Copy)]
struct Here {
    at: [Ne; MAX_FENCES],
}

/// The stopping trajectory of a horizontal velocity command `w` from current
/// velocity `c`, as segments (offsets from the vehicle), and the rounding slack of
/// its chords. Three vehicle models, all checked:
/// - the command takes effect after `lag` s at `c`, then the velocity changes from
///   `c` to `w` at `a` (a parabola, followed in chords): a stop may come at any
///   point of it, so from every chord point a braking segment along the velocity
///   there (`u·|u|/2a`), the first being the stop along `c` alone;
/// - the command takes effect at once after the lag, and the vehicle brakes along
///   `w` from `|w|`;
/// - the vehicle already flies `w` during the lag (setpoints on their way), then
///   brakes along it.
fn stopping_trajectory(
    c: Ne,
    w: Ne,
    lag: f64,
    a: f64,
    out: &mut [Segment; MAX_SEGMENTS],
) -> (usize, f64) {
    let brake = |u: Ne| u * (u.norm() / (2.0 * a));
    let mut n = 0;
    let mut push = |seg: Segment, n: &mut usize| {
        out[*n] = seg;
        *n += 1;
    };
    let o1 = c * lag;
    push((Ne::zeros(), o1), &mut n);
    push((o1, o1 + brake(w)), &mut n);
    // Setpoints already on their way may have it flying at `w` during the lag.
    let ow = w * lag;
    push((Ne::zeros(), ow), &mut n);
    push((ow, ow + brake(w)), &mut n);
    push((o1, o1 + brake(c)), &mut n);
    let dv = w - c;
    let tau = dv.norm() / a;
    if tau <= 0.0 {
        return (n, 0.0);
    }
    let dir = dv / dv.norm();
    let chords = ((tau / CHORD_S).ceil() as usize).clamp(1, MAX_CHORDS);
    let dt = tau / chords as f64;
    let at = |t: f64| {
        let q = o1 + c * t + dir * (0.5 * a * t * t);
        (q, q + brake(c + dir * (a * t)))
    };
    let (mut prev, mut prev_end) = (o1, o1 + brake(c));
    let mut slack: f64 = 0.0;
    for i in 1..=chords {
        let t = dt * i as f64;
        let (q, end) = if i == chords {
            let q = o1 + c * t + dir * (0.5 * a * t * t);
            (q, q + brake(w))
        } else {
            at(t)
        };
        push((prev, q), &mut n);
        push((q, end), &mut n);
        // A brake begun between two chord points ends between their stopping
        // points: the curve of stopping points, followed in chords too.
        push((prev_end, end), &mut n);
        // How far each curve strays from its chord, measured at the middle: exact
        // for the path (a parabola: constant second derivative), and with half
        // again for the stopping points, whose second derivative varies (≤ 3a).
        let (q_mid, end_mid) = at(t - 0.5 * dt);
        slack = slack
            .max(point_segment_dist2(q_mid, prev, q).sqrt())
            .max(1.5 * point_segment_dist2(end_mid, prev_end, end).sqrt());
        prev = q;
        prev_end = end;
    }
    (n, slack)
}

impl FenceStack {
    fn here(&self, lat_deg: f64, lon_deg: f64) -> Here {
        let mut at = [Ne::zeros(); MAX_FENCES];
        for (slot, f) in at.iter_mut().zip(self.fences()) {
            *slot = f.frame.to_local(lat_deg, lon_deg);
        }
        Here { at }
    }

    /// Clearance of the vehicle (the smallest over the fences; 0 when outside one).
    fn clearance(&self, here: &Here) -> f64 {
        self.fences()
            .zip(here.at)
            .map(|(f, p)| f.clearance(p))
            .fold(f64::INFINITY, f64::min)
    }

    /// Every segment is clear by `r` in every fence.
    fn clear(&self, here: &Here, segments: &[Segment], r: f64) -> bool {
        self.fences().zip(here.at).all(|(f, p)| {
            segments
                .iter()
                .all(|(a, b)| f.segment_clear(p + a, p + b, r))
        })
    }

    /// The unit direction from the nearest boundary point of any fence toward the
    /// vehicle (inward when inside), and that point's distance.
    fn away_from_nearest(&self, here: &Here) -> Option<(Ne, f64)> {
        self.fences()
            .zip(here.at)
            .filter_map(|(f, p)| {
                let q = f.nearest_boundary(p)?;
                Some(((p - q).try_normalize(1e-9)?, (p - q).norm()))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// Limits a NED velocity setpoint so that the vehicle at `k` stops inside every
    /// fence, at least the margin from each boundary (measured perpendicular to it).
    ///
    /// Horizontally, the stopping trajectory of the command ([`stopping_trajectory`];
    /// lag = `response_s` + the fix's age, deceleration `decel_mps2`) must be clear
    /// by the margin — or, when the vehicle is already closer, by its own clearance
    /// (it may move along or away from the boundary, not closer). The command is
    /// kept when it passes, else scaled down to the largest fraction that passes
    /// (bisection); when even a stop (fraction 0) does not pass because the current
    /// velocity carries the vehicle on, it is replaced by a velocity pointing back
    /// in (away from the nearest boundary), which makes the autopilot brake at its
    /// full rate. Outside a fence only the component back toward it is kept. With a
    /// fix older than [`MAX_FIX_AGE_S`], a command toward the nearest boundary is
    /// zeroed, and no vertical motion is allowed. Vertically, the lowest ceiling and
    /// the highest floor with the vertical margin.
    pub fn limit_velocity(
        &self,
        env: &Envelope,
        k: &Kinematics,
        command: [f32; 3],
        max_speed_mps: f32,
    ) -> ([f32; 3], Option<Limit>) {
        let mut out = command;
        let mut limit = None;
        if self.is_empty() {
            return (out, None);
        }
        let stale = k.age_s > MAX_FIX_AGE_S;
        let age = f64::from(k.age_s.max(0.0));
        let lag = env.response_s + age;
        let a = env.decel_mps2;
        let here = self.here(k.lat_deg, k.lon_deg);
        let c = Ne::new(k.vel_ned_mps[0].into(), k.vel_ned_mps[1].into());
        let mut w = Ne::new(command[0].into(), command[1].into());
        let d0 = self.clearance(&here);
        let horizontal = if d0 <= 0.0 {
            // Outside one of the fences: back toward the first one it is outside of.
            let back = self
                .fences()
                .zip(here.at)
                .find(|(f, p)| !f.contains(*p))
                .and_then(|(f, p)| f.way_back(p))
                .unwrap_or_else(Ne::zeros);
            let kept = back * w.dot(&back).max(0.0);
            ((kept - w).norm() > 1e-3).then_some((kept, Limit::Outside))
        } else {
            let mut why = None;
            let nearest = self.away_from_nearest(&here);
            if stale && w.norm() > 1e-3 {
                if let Some((away, _)) = nearest {
                    if w.dot(&away) < 0.0 {
                        w = Ne::zeros();
                        why = Some(Limit::StaleFix { age_s: k.age_s });
                    }
                }
            }
            let r = env.margin_m.min(d0 - EPS_M).max(0.0);
            let mut segments = [(Ne::zeros(), Ne::zeros()); MAX_SEGMENTS];
            let mut safe = |v: Ne| {
                let (n, slack) = stopping_trajectory(c, v, lag, a, &mut segments);
                // The chords' slack, but never more than the start has (in the band
                // the rule is "no closer than now").
                let r = if d0 >= env.margin_m {
                    (r + slack + MODEL_SLACK_M).min(d0 - EPS_M).max(r)
                } else {
                    (r + slack).min(d0 - EPS_M).max(0.0)
                };
                self.clear(&here, &segments[..n], r)
            };
            if safe(w) {
                why.map(|y| (w, y))
            } else if safe(Ne::zeros()) {
                let (mut lo, mut hi) = (0.0, 1.0);
                for _ in 0..BISECT_STEPS {
                    let mid = 0.5 * (lo + hi);
                    if safe(w * mid) {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                // A crawl is a stop (the bisection's last step is not a command).
                let to = if w.norm() * lo < 0.01 {
                    Ne::zeros()
                } else {
                    w * lo
                };
                Some((
                    to,
                    why.unwrap_or(Limit::Boundary {
                        from: w.norm(),
                        to: to.norm(),
                    }),
                ))
            } else {
                let away = nearest.map_or(Ne::zeros(), |(away, _)| away);
                let speed = w.dot(&away).max(BACK_IN_MPS).min(max_speed_mps.into());
                Some((away * speed, Limit::BackIn { clearance_m: d0 }))
            }
        };
        if let Some((h, why)) = horizontal {
            out[0] = h.x as f32;
            out[1] = h.y as f32;
            limit = Some(why);
        }
        // Vertical, NED: positive down.
        let up = -f64::from(command[2]);
        let cur_up = -f64::from(k.vel_ned_mps[2]);
        let alt = f64::from(k.alt_rel_m);
        let ceiling = f64::from(self.ceiling_m().unwrap_or(f32::MAX));
        let floor = f64::from(self.floor_m().unwrap_or(f32::MIN));
        let vertical = if up > 0.0 {
            let room = ceiling - env.vertical_margin_m - alt - cur_up.max(0.0) * lag;
            let allowed = if alt > ceiling || stale {
                0.0
            } else {
                stoppable(room, a)
            };
            (up > allowed).then_some((allowed, Limit::Ceiling))
        } else if up < 0.0 {
            let room = alt - floor - env.vertical_margin_m - (-cur_up).max(0.0) * lag;
            let allowed = if alt < floor || stale {
                0.0
            } else {
                stoppable(room, a)
            };
            (-up > allowed).then_some((-allowed, Limit::Floor))
        } else {
            None
        };
        if let Some((allowed_up, why)) = vertical {
            out[2] = -allowed_up as f32;
            limit = limit.or(Some(if stale {
                Limit::StaleFix { age_s: k.age_s }
            } else {
                why
            }));
        }
        (out, limit)
    }

    /// Checks a straight flight from `from` (the vehicle, `None` if unknown) to
    /// `to` (lat, lon): the target at least `margin_m` inside every fence; from
    /// inside, every point of the path at least the margin from every boundary (or,
    /// from closer, no closer than the start); from outside a fence (and not in a
    /// keep-out), a path that enters once and stays in, and passes no keep-out
    /// within the margin. An unknown position is refused: the path cannot be
    /// checked. `Err` says why.
    pub fn check_path(
        &self,
        from: Option<(f64, f64)>,
        to: (f64, f64),
        margin_m: f64,
        scratch: &mut Vec<f64>,
    ) -> Result<(), String> {
        if self.is_empty() {
            return Ok(());
        }
        let target = self.here(to.0, to.1);
        if self.clearance(&target) <= 0.0 {
            return Err("target outside the fence".to_string());
        }
        if !self.clear(&target, &[(Ne::zeros(), Ne::zeros())], margin_m) {
            return Err(format!("target within {margin_m:.1} m of the fence"));
        }
        let Some(from) = from else {
            return Err("position unknown: path not checked".to_string());
        };
        let here = self.here(from.0, from.1);
        let d0 = self.clearance(&here);
        let n = self.len();
        if d0 > 0.0 {
            let r = margin_m.min(d0 - EPS_M).max(0.0);
            let ok = self
                .fences()
                .zip(here.at)
                .zip(target.at)
                .all(|((f, p), t)| f.segment_clear(p, t, r));
            return if ok {
                Ok(())
            } else {
                Err(format!("path passes within {r:.1} m of the fence"))
            };
        }
        let fences = || self.fences().zip(here.at[..n].iter().zip(&target.at[..n]));
        if fences().any(|(f, (p, _))| f.in_keep_out(*p)) {
            return Err("vehicle in a keep-out: fly out first".to_string());
        }
        if !fences().all(|(f, (p, t))| f.segment_clear_of_keep_outs(*p, *t, margin_m)) {
            return Err("path from outside nears a keep-out".to_string());
        }
        // Outside a keep-in: once the path is inside every keep-in it must stay.
        scratch.clear();
        for (f, (p, t)) in fences() {
            f.keep_in_crossings(*p, *t, scratch);
        }
        scratch.push(1.0);
        scratch.sort_unstable_by(f64::total_cmp);
        let mut entered = false;
        let mut last = 0.0;
        for &u in scratch.iter() {
            let mid = 0.5 * (last + u);
            last = u;
            let inside = fences().all(|(f, (p, t))| f.contains(p + (t - p) * mid));
            if entered && !inside {
                return Err("path from outside leaves the fence again".to_string());
            }
            entered |= inside;
        }
        Ok(())
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
    use crate::arbiter::tests::{executed, flying, refusal, sample, settings, S};
    use crate::arbiter::VehicleView;
    use proptest::prelude::*;
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

    // ---- The velocity envelope and the path check over the stack ----

    fn envelope() -> Envelope {
        let s = settings();
        Envelope {
            decel_mps2: s.fence_deceleration_mps2.into(),
            margin_m: s.fence_margin_m.into(),
            vertical_margin_m: s.fence_vertical_margin_m.into(),
            response_s: s.fence_response_s.into(),
        }
    }

    fn at(p: Ne, vel: Ne, age_s: f32) -> Kinematics {
        let [lat_deg, lon_deg] = ll(p.x, p.y);
        Kinematics {
            lat_deg,
            lon_deg,
            alt_rel_m: 10.0,
            vel_ned_mps: [vel.x as f32, vel.y as f32, 0.0],
            age_s,
        }
    }

    /// Flies a vehicle (setpoints take effect `lag` s late, velocity follows them at
    /// up to `accel`) on `command` through the envelope every 20 ms for `secs`, then
    /// stops the stream (a zero setpoint) until it rests. Returns the largest value
    /// of `toward(position)` seen and the rest position.
    fn fly(
        stack: &FenceStack,
        start: Ne,
        vel: Ne,
        command: Ne,
        secs: f64,
        toward: impl Fn(Ne) -> f64,
    ) -> (f64, Ne) {
        let (worst, (p, _)) = fly_from(stack, (start, vel), command, secs, true, toward);
        (worst, p)
    }

    /// [`fly`] from a state, stopping the stream at the end only if `stop` (else
    /// returns the state after `secs`; the next leg starts with the current velocity
    /// for the setpoints on their way).
    fn fly_from(
        stack: &FenceStack,
        (start, vel): (Ne, Ne),
        command: Ne,
        secs: f64,
        stop: bool,
        toward: impl Fn(Ne) -> f64,
    ) -> (f64, (Ne, Ne)) {
        let env = envelope();
        let (dt, lag, accel) = (0.02, 0.3, 2.5);
        let delay = (lag / dt) as usize;
        let (mut p, mut v) = (start, vel);
        let mut queue = std::collections::VecDeque::from(vec![vel; delay]);
        let mut worst = toward(p);
        let steps = (secs / dt) as usize;
        let total = if stop { steps + 2000 } else { steps };
        for i in 0..total {
            let sp = if i < steps {
                let (out, _) = stack.limit_velocity(
                    &env,
                    &at(p, v, 0.0),
                    [command.x as f32, command.y as f32, 0.0],
                    12.0,
                );
                Ne::new(out[0].into(), out[1].into())
            } else {
                Ne::zeros()
            };
            queue.push_back(sp);
            let target = queue.pop_front().unwrap();
            let dv = target - v;
            let step = accel * dt;
            v += if dv.norm() > step {
                dv * (step / dv.norm())
            } else {
                dv
            };
            p += v * dt;
            worst = worst.max(toward(p));
        }
        if stop {
            assert!(v.norm() < 1e-6, "came to rest");
        }
        (worst, (p, v))
    }

    fn boxed(source: CommandSource) -> Arbiter {
        let mut a = Arbiter::new(settings());
        a.set_geofence(&keep_in(source, (-50.0, 50.0), (-50.0, 50.0)), 1);
        a
    }

    #[test]
    fn at_ten_degrees_incidence_the_vehicle_stops_the_margin_from_the_wall() {
        let a = boxed(SwarmQueue);
        let margin = envelope().margin_m;
        // 5 m/s at 10 degrees to the north wall (x = 50), for 30 s: along the ray the
        // wall is 115 m away, perpendicular 20 m.
        let dir = Ne::new(10f64.to_radians().sin(), 10f64.to_radians().cos());
        let (north, rest) = fly(
            a.fence(),
            Ne::new(30.0, -45.0),
            Ne::zeros(),
            dir * 5.0,
            30.0,
            |p| p.x,
        );
        assert!(north <= 50.0 - margin + 1e-6, "{north} (rest {rest:?})");
        // It did fly on along the wall and toward it as far as allowed.
        assert!(north > 50.0 - margin - 4.0, "{north}");
        // Shallower still: 2 degrees.
        let dir = Ne::new(2f64.to_radians().sin(), 2f64.to_radians().cos());
        let (north, _) = fly(
            a.fence(),
            Ne::new(44.0, -45.0),
            Ne::zeros(),
            dir * 8.0,
            12.0,
            |p| p.x,
        );
        assert!(north <= 50.0 - margin + 1e-6, "{north}");
    }

    #[test]
    fn the_current_velocity_toward_a_wall_counts_when_the_command_points_elsewhere() {
        let a = boxed(SwarmQueue);
        let env = envelope();
        // 5 m/s east toward the east wall (y = 50) 3 m away, commanded north: no
        // braking distance left, so the envelope commands back in (westward).
        let k = at(Ne::new(0.0, 47.0), Ne::new(0.0, 5.0), 0.0);
        let (out, why) = a.fence().limit_velocity(&env, &k, [3.0, 0.0, 0.0], 12.0);
        assert!(matches!(why, Some(Limit::BackIn { .. })), "{why:?}");
        assert!(out[1] < 0.0, "points back in: {out:?}");
        // 12 m away the stop fits (1.5 m lag + 8.3 m braking + 2 m margin): the
        // vehicle flown north on that command never comes within the margin.
        let (east, _) = fly(
            a.fence(),
            Ne::new(0.0, 38.0),
            Ne::new(0.0, 5.0),
            Ne::new(3.0, 0.0),
            5.0,
            |p| p.y,
        );
        assert!(east <= 50.0 - env.margin_m + 1e-6, "{east}");
        // Moving east is also limited when the command only continues it.
        let k = at(Ne::new(0.0, 30.0), Ne::new(0.0, 5.0), 0.0);
        let (out, why) = a.fence().limit_velocity(&env, &k, [0.0, 8.0, 0.0], 12.0);
        assert!(matches!(why, Some(Limit::Boundary { .. })), "{why:?}");
        assert!(out[1] < 8.0 && out[1] > 0.0, "{out:?}");
    }

    #[test]
    fn a_stale_fix_refuses_motion_toward_the_boundary_and_adds_its_age() {
        let a = boxed(SwarmQueue);
        let env = envelope();
        let toward = [0.0, 2.0, 0.0];
        let fresh = at(Ne::new(0.0, 30.0), Ne::zeros(), 0.1);
        let (out, why) = a.fence().limit_velocity(&env, &fresh, toward, 12.0);
        assert_eq!((out, why), (toward, None), "fresh: free");
        let stale = at(Ne::new(0.0, 30.0), Ne::zeros(), 0.8);
        let (out, why) = a.fence().limit_velocity(&env, &stale, toward, 12.0);
        assert_eq!(out, [0.0; 3]);
        assert_eq!(why, Some(Limit::StaleFix { age_s: 0.8 }));
        assert_eq!(
            why.unwrap().to_string(),
            "fix 0.8 s old: no motion to fence"
        );
        // Away from the nearest wall is still allowed.
        let (out, why) = a
            .fence()
            .limit_velocity(&env, &stale, [0.0, -2.0, 0.0], 12.0);
        assert_eq!((out, why), ([0.0, -2.0, 0.0], None));
        // The age lengthens the stop: moving east at 4 m/s 13 m from the wall, a
        // 0.4 s old fix allows less than a fresh one.
        let speed = |age| {
            let k = at(Ne::new(0.0, 37.0), Ne::new(0.0, 4.0), age);
            a.fence().limit_velocity(&env, &k, [0.0, 6.0, 0.0], 12.0).0[1]
        };
        assert!(speed(0.4) < speed(0.0), "{} {}", speed(0.4), speed(0.0));
    }

    #[test]
    fn inside_the_margin_only_along_or_away() {
        let a = boxed(SwarmQueue);
        let env = envelope();
        let k = at(Ne::new(0.0, 49.0), Ne::zeros(), 0.0);
        let (out, _) = a.fence().limit_velocity(&env, &k, [0.0, 1.0, 0.0], 12.0);
        assert_eq!(out, [0.0; 3], "closer: no");
        let (out, why) = a.fence().limit_velocity(&env, &k, [0.0, -3.0, 0.0], 12.0);
        assert_eq!((out, why), ([0.0, -3.0, 0.0], None), "away: free");
        // Outside: only the way back.
        let k = at(Ne::new(0.0, 55.0), Ne::zeros(), 0.0);
        let (out, why) = a.fence().limit_velocity(&env, &k, [1.0, -2.0, 0.0], 12.0);
        assert_eq!(why, Some(Limit::Outside));
        assert!(
            out[0].abs() < 1e-3 && (out[1] + 2.0).abs() < 1e-3,
            "{out:?}"
        );
    }

    #[test]
    fn two_fences_hold_together_and_the_box_alone_after_the_other_is_cleared() {
        let mut a = boxed(SwarmQueue);
        a.set_geofence(&keep_in(ShotEngine, (-20.0, 20.0), (-20.0, 20.0)), 1);
        let env = envelope();
        // North at 5 m/s from the middle: the Solo fence (x = 20) is the nearer wall.
        let (north, _) = fly(
            a.fence(),
            Ne::zeros(),
            Ne::zeros(),
            Ne::new(5.0, 0.0),
            20.0,
            |p| p.x,
        );
        assert!(
            north <= 20.0 - env.margin_m + 1e-6 && north > 17.0,
            "{north}"
        );
        a.set_geofence(&clear(ShotEngine, None, 1), 1);
        let (north, _) = fly(
            a.fence(),
            Ne::zeros(),
            Ne::zeros(),
            Ne::new(5.0, 0.0),
            30.0,
            |p| p.x,
        );
        assert!(
            north <= 50.0 - env.margin_m + 1e-6 && north > 47.0,
            "box: {north}"
        );
        // Lowest ceiling, highest floor.
        let mut low = keep_in(Vision, (-100.0, 100.0), (-100.0, 100.0));
        low.ceiling_m = 12.0;
        a.set_geofence(&low, 1);
        let k = at(Ne::zeros(), Ne::zeros(), 0.0);
        let (out, why) = a.fence().limit_velocity(&env, &k, [0.0, 0.0, -3.0], 12.0);
        assert_eq!(why, Some(Limit::Ceiling));
        assert!(
            (out[2] + (2.0f32 * 1.5 * 1.0).sqrt()).abs() < 1e-3,
            "{out:?}"
        );
    }

    fn goto_none(north: f64, east: f64) -> Command {
        let [lat_deg, lon_deg] = ll(north, east);
        Command::GoTo {
            lat_deg,
            lon_deg,
            alt_rel_m: 10.0,
            yaw_deg: None,
            speed_mps: None,
        }
    }

    #[test]
    fn goto_always_carries_a_capped_speed() {
        let mut a = Arbiter::new(settings());
        let v = flying(0.0, 0.0, [0.0; 3]);
        let d = a.decide(S, &sample(Operator, goto_none(10.0, 0.0), S), &v);
        let Command::GoTo { speed_mps, .. } = executed(&d) else {
            unreachable!()
        };
        assert_eq!(speed_mps, Some(settings().max_horizontal_speed_mps));
        let mut fast = goto_none(10.0, 0.0);
        if let Command::GoTo { speed_mps, .. } = &mut fast {
            *speed_mps = Some(20.0);
        }
        let d = a.decide(S, &sample(Operator, fast, S), &v);
        assert_eq!(d.result(), AckResult::Limited);
    }

    #[test]
    fn goto_under_a_fence_needs_a_position_a_clear_path_and_a_target_inside_the_margin() {
        let mut a = boxed(SwarmQueue);
        let mut with_keep_out = keep_in(Operator, (-100.0, 100.0), (-100.0, 100.0));
        // A keep-out between 60 and 70 m east, from south to north of the box.
        let out_ring = [
            ll(-80.0, 60.0),
            ll(80.0, 60.0),
            ll(80.0, 70.0),
            ll(-80.0, 70.0),
        ];
        assert!(with_keep_out.push_polygon(FenceKind::KeepOut, &out_ring));
        a.set_geofence(&with_keep_out, 1);
        // Unknown position: refused with the fence, clearly.
        let d = a.decide(
            S,
            &sample(Operator, goto_none(10.0, 0.0), S),
            &VehicleView::default(),
        );
        assert_eq!(
            refusal(&d),
            (
                RefusalReason::Geofence,
                "position unknown: path not checked"
            )
        );
        let takeoff = Command::Takeoff { alt_rel_m: 10.0 };
        let d = a.decide(S, &sample(Operator, takeoff, S), &VehicleView::default());
        assert_eq!(
            refusal(&d),
            (
                RefusalReason::Geofence,
                "position unknown: takeoff not checked"
            )
        );
        // From outside (80 m east, beyond the keep-out), back in through it: refused.
        let outside = flying(0.0, 80.0, [0.0; 3]);
        let d = a.decide(S, &sample(Operator, goto_none(0.0, 0.0), S), &outside);
        assert_eq!(
            refusal(&d),
            (
                RefusalReason::Geofence,
                "path from outside nears a keep-out"
            )
        );
        // From outside the box but not beyond the keep-out (55 m east): back in, fine.
        let near = flying(0.0, 55.0, [0.0; 3]);
        let d = a.decide(S, &sample(Operator, goto_none(0.0, 30.0), S), &near);
        assert_ne!(d.result(), AckResult::Refused, "{d:?}");
        // ... but not to a target within the margin of the wall.
        let d = a.decide(S, &sample(Operator, goto_none(0.0, 49.0), S), &near);
        assert_eq!(
            refusal(&d),
            (RefusalReason::Geofence, "target within 2.0 m of the fence")
        );
        // From inside: a path that grazes the north wall closer than the margin.
        let v = flying(40.0, -40.0, [0.0; 3]);
        let d = a.decide(S, &sample(Operator, goto_none(40.0, 40.0), S), &v);
        assert_ne!(d.result(), AckResult::Refused, "parallel, 10 m off: {d:?}");
        let d = a.decide(S, &sample(Operator, goto_none(47.0, 0.0), S), &v);
        assert_eq!(d.result(), AckResult::Accepted, "3 m off: {d:?}");
        let mut bent = keep_in(Vision, (-100.0, 100.0), (-100.0, 100.0));
        // A notch in the north wall of a U-shaped Vision fence the path cuts across.
        bent.polygons[0] = Default::default();
        bent.polygon_count = 0;
        let u = [
            ll(-100.0, -100.0),
            ll(100.0, -100.0),
            ll(100.0, -10.0),
            ll(41.0, -10.0),
            ll(41.0, 10.0),
            ll(100.0, 10.0),
            ll(100.0, 100.0),
            ll(-100.0, 100.0),
        ];
        assert!(bent.push_polygon(FenceKind::KeepIn, &u));
        a.set_geofence(&bent, 1);
        let d = a.decide(S, &sample(Operator, goto_none(40.0, 40.0), S), &v);
        assert_eq!(
            refusal(&d),
            (
                RefusalReason::Geofence,
                "path passes within 2.0 m of the fence"
            )
        );
        // Takeoff outside the fences refused; at the box's edge fine.
        let d = a.decide(S, &sample(Operator, takeoff, S), &outside);
        assert_eq!(
            refusal(&d),
            (RefusalReason::Geofence, "vehicle outside the fence")
        );
    }

    // ---- Property: the simulated stop never comes within the margin ----

    /// A star-shaped (often concave) keep-in around home: `radii` at even angles
    /// with `jitter` (fractions of the step).
    fn star(source: CommandSource, radii: &[f64], jitter: &[f64]) -> GeofenceSet {
        let n = radii.len();
        let ring: Vec<[f64; 2]> = (0..n)
            .map(|i| {
                let step = std::f64::consts::TAU / n as f64;
                let angle = step * (i as f64 + 0.4 * jitter[i % jitter.len()]);
                ll(radii[i] * angle.cos(), radii[i] * angle.sin())
            })
            .collect();
        let mut set = GeofenceSet {
            vehicle_id: 1,
            enabled: 1,
            source: source.to_wire(),
            ..Default::default()
        };
        assert!(set.push_polygon(FenceKind::KeepIn, &ring));
        set
    }

    /// A square keep-out of half-size `half` around `center` (home metres).
    fn keep_out(source: CommandSource, center: Ne, half: f64) -> GeofenceSet {
        let (n0, n1, e0, e1) = (
            center.x - half,
            center.x + half,
            center.y - half,
            center.y + half,
        );
        let mut set = GeofenceSet {
            vehicle_id: 1,
            enabled: 1,
            source: source.to_wire(),
            ..Default::default()
        };
        assert!(set.push_polygon(
            FenceKind::KeepOut,
            &[ll(n0, e0), ll(n1, e0), ll(n1, e1), ll(n0, e1)]
        ));
        set
    }

    /// Independent of the envelope: inside every fence and the distance to the
    /// nearest edge of any polygon (for a point inside, the distance to outside).
    fn true_clearance(stack: &FenceStack, p: Ne) -> f64 {
        let [lat, lon] = ll(p.x, p.y);
        if !stack.contains(lat, lon) {
            return 0.0;
        }
        stack
            .fences()
            .flat_map(|f| {
                let q = f.frame.to_local(lat, lon);
                f.polygons.iter().map(move |poly| poly.boundary_distance(q))
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// The vehicle from `p` at `c`: `lag` s at `c`, then its velocity goes to `w`
    /// at `accel` (`None`: at once) for `hold` s, then it brakes at `decel` along its
    /// velocity. The smallest clearance on the way (sampled every 10 ms).
    fn simulate(
        stack: &FenceStack,
        (p, c, w): (Ne, Ne, Ne),
        (lag, hold): (f64, f64),
        accel: Option<f64>,
        decel: f64,
    ) -> f64 {
        let dt = 0.01;
        let (mut p, mut v) = (p, c);
        let mut worst = true_clearance(stack, p);
        let mut t = 0.0;
        let mut braking = false;
        while t < 60.0 {
            // (t is a sum of 10 ms steps and the lag an f32 setting widened: not
            // one step late by rounding.)
            if t >= lag + hold - 1e-6 {
                braking = true;
            }
            let target = if braking {
                Ne::zeros()
            } else if t >= lag - 1e-6 {
                w
            } else {
                c
            };
            let dv = target - v;
            let step = if braking {
                decel * dt
            } else {
                accel.map_or(f64::INFINITY, |a| a * dt)
            };
            let v_next = if dv.norm() > step {
                v + dv * (step / dv.norm())
            } else {
                target
            };
            // At once means at once: no step averaging the old velocity in.
            p += if step.is_infinite() {
                v_next * dt
            } else {
                (v + v_next) * (0.5 * dt)
            };
            v = v_next;
            worst = worst.min(true_clearance(stack, p));
            t += dt;
            if braking && v.norm() < 1e-9 {
                break;
            }
        }
        worst
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 300,
            max_global_rejects: 50_000,
            ..ProptestConfig::default()
        })]

        #[test]
        fn the_stop_never_comes_within_the_margin(
            radii in proptest::collection::vec(30.0f64..120.0, 3..12),
            jitter in proptest::collection::vec(-1.0f64..1.0, 12),
            second in 0u8..3,
            other_center in (-60.0f64..60.0, -60.0f64..60.0),
            other_half in 3.0f64..25.0,
            pos in (-100.0f64..100.0, -100.0f64..100.0),
            vel in (-8.0f64..8.0, -8.0f64..8.0),
            cmd in (-12.0f64..12.0, -12.0f64..12.0),
            hold_frac in 0.0f64..1.2,
            instant in any::<bool>(),
        ) {
            let mut a = Arbiter::new(settings());
            a.set_geofence(&star(SwarmQueue, &radii, &jitter), 1);
            let center = Ne::new(other_center.0, other_center.1);
            match second {
                1 => {
                    a.set_geofence(&keep_out(ShotEngine, center, other_half), 1);
                }
                2 => {
                    let h = 3.0 * other_half;
                    a.set_geofence(
                        &keep_in(ShotEngine, (center.x - h, center.x + h), (center.y - h, center.y + h)),
                        1,
                    );
                }
                _ => {}
            }
            let stack = a.fence();
            let env = envelope();
            let (p, c, w) = (Ne::new(pos.0, pos.1), Ne::new(vel.0, vel.1), Ne::new(cmd.0, cmd.1));
            // Started at least margin + epsilon inside, and able to stop there.
            prop_assume!(true_clearance(stack, p) >= env.margin_m + MODEL_SLACK_M + 0.05);
            let zero = simulate(stack, (p, c, Ne::zeros()), (env.response_s, 0.0), Some(env.decel_mps2), env.decel_mps2);
            prop_assume!(zero >= env.margin_m + MODEL_SLACK_M);
            let (out, why) = stack.limit_velocity(&env, &at(p, c, 0.0), [cmd.0 as f32, cmd.1 as f32, 0.0], 12.0);
            let v = Ne::new(out[0].into(), out[1].into());
            prop_assert!(!matches!(why, Some(Limit::BackIn { .. })), "{why:?}");
            // Following the command at the assumed rate, braked at any moment of the
            // change of velocity (after that the next decision takes over); or
            // taking it at once, at the start or the end of the lag, then braked.
            let tau = (v - c).norm() / env.decel_mps2;
            let lag = env.response_s;
            let worst = if instant {
                simulate(stack, (p, c, v), (lag, 0.0), None, env.decel_mps2)
                    .min(simulate(stack, (p, v, v), (lag, 0.0), None, env.decel_mps2))
            } else {
                let hold = hold_frac.min(1.0) * tau;
                simulate(stack, (p, c, v), (lag, hold), Some(env.decel_mps2), env.decel_mps2)
            };
            prop_assert!(
                worst >= env.margin_m - 1e-6,
                "closest {worst:.3} m; command {w:?} -> {v:?} ({why:?}), hold {hold_frac:.2}, instant {instant}"
            );
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 12,
            max_global_rejects: 5_000,
            ..ProptestConfig::default()
        })]

        /// Closed loop: a stream of random commands decided every 20 ms, the vehicle
        /// 0.3 s behind its setpoints and following them at 2.5 m/s² (faster than the
        /// envelope assumes), then the stream stops: never within the margin.
        #[test]
        fn a_closed_loop_stream_never_comes_within_the_margin(
            radii in proptest::collection::vec(40.0f64..120.0, 3..10),
            jitter in proptest::collection::vec(-1.0f64..1.0, 12),
            pos in (-30.0f64..30.0, -30.0f64..30.0),
            cmds in proptest::collection::vec((-12.0f64..12.0, -12.0f64..12.0), 1..4),
            secs in 2.0f64..6.0,
        ) {
            let mut a = Arbiter::new(settings());
            a.set_geofence(&star(SwarmQueue, &radii, &jitter), 1);
            let stack = a.fence();
            let env = envelope();
            let p = Ne::new(pos.0, pos.1);
            prop_assume!(true_clearance(stack, p) >= env.margin_m + 0.05);
            let mut worst = f64::INFINITY;
            let per = secs / cmds.len() as f64;
            let mut start = (p, Ne::zeros());
            for (i, cmd) in cmds.iter().enumerate() {
                let last = i + 1 == cmds.len();
                let (w, end) = fly_from(stack, start, Ne::new(cmd.0, cmd.1), per, last, |q| {
                    -true_clearance(stack, q)
                });
                worst = worst.min(-w);
                start = end;
            }
            prop_assert!(worst >= env.margin_m - 5e-3, "closest {worst:.3} m");
        }
    }
}
