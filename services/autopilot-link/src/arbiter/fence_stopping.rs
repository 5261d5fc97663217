//! The velocity limit and the path check over the fence stack: the stopping
//! trajectory of a command (three vehicle models) must stay the margin inside every
//! fence ([`FenceStack::limit_velocity`]), and a straight flight to a target must keep
//! the margin from every boundary ([`FenceStack::check_path`]).

use super::fence_stack::{FenceStack, MAX_FENCES};
use super::geofence::{point_segment_dist2, stoppable, Envelope, Limit, Ne, MAX_FIX_AGE_S};
use super::Kinematics;

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
