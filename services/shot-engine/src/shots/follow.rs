//! Follow: track the phone's GPS stream (UDP 14558, ~25 Hz) in one of the Solo's
//! follow styles. The fixes are smoothed by an alpha-beta filter so GPS jitter does
//! not shake the vehicle, and the target's velocity is fed forward so the vehicle
//! keeps up without lagging behind.

use nalgebra::{Vector2, Vector3};

use super::geo::{GeoPoint, LocalFrame};
use super::motion::{
    clamp_norm2, dt64, sqrt_controller, to_f32, HoldPoint, Lim, Shaper, VELOCITY_LAG_S,
};
use super::{Guidance, Limits, VehicleView};

/// A target without a fix for this long is lost: the vehicle hovers, seconds.
pub const DEFAULT_STALE_AFTER_S: f64 = 2.0;

/// The vehicle keeps at least this far (horizontally) from the target, metres.
pub const MIN_FOLLOW_DISTANCE_M: f64 = 2.0;

/// Time constant of the target filter, seconds: jitter faster than this is smoothed
/// away, the filter settles on a new velocity within a few of them.
const FILTER_TAU_S: f64 = 0.7;

/// Share of the speed limit the offset may use to orbit plus the target's own speed;
/// the rest corrects position errors.
const SPEED_SHARE: f64 = 0.9;

/// Leash: over the last metre before the leash is taut the target's velocity is fed
/// forward progressively, so taking up slack is smooth.
const LEASH_TAKE_UP_M: f64 = 1.0;

/// How the vehicle follows the target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FollowMode {
    /// Preference 0 "hold angle": keep the offset to the target, orbit it at cruise
    /// speed; camera on the target.
    Orbit,
    /// Preference 1: translate with the target keeping the offset, camera left to the
    /// pilot (cruise speed does not orbit: the app switches to Orbit for that).
    FreeLook,
    /// Preference 2: trail behind at the leash length (the distance when the mode
    /// began), move only when farther; camera on the target.
    Leash,
    /// lookAt = 1: stay put, camera on the target.
    LookAt,
}

/// The smoothed target, NED in the follow frame.
#[derive(Debug, Clone, Copy)]
struct Track {
    pos: Vector3<f64>,
    vel: Vector3<f64>,
    /// When the last fix arrived, monotonic seconds.
    at_s: f64,
    /// When the filter (re)started.
    since_s: f64,
    /// Fixes since then.
    fixes: u32,
}

impl Track {
    /// Settled enough to take an offset or a leash length from: a single fix can be
    /// metres off, the filter after a time constant is not.
    fn warmed_up(&self) -> bool {
        self.fixes >= 2 && self.at_s - self.since_s >= FILTER_TAU_S
    }
}

/// Follow the phone.
#[derive(Debug, Clone)]
pub struct Follow {
    /// NED around where the vehicle was when the shot began.
    frame: LocalFrame,
    mode: FollowMode,
    track: Option<Track>,
    stale_after_s: f64,
    /// The latest time seen (fix or step), monotonic seconds.
    now_s: f64,
    /// Orbit/FreeLook: target → vehicle, horizontal; latched on the first step with a
    /// target after a mode change.
    offset: Option<Vector2<f64>>,
    /// Leash length, latched like `offset`.
    leash_m: Option<f64>,
    /// Altitude held, NED down.
    hold_down: f64,
    look_at: HoldPoint,
    shaper: Shaper,
}

impl Follow {
    /// A follow in [`FollowMode::Orbit`] that waits for the first target, holding the
    /// vehicle's altitude.
    pub fn new(v: &VehicleView) -> Follow {
        Follow {
            frame: LocalFrame::new(v.position),
            mode: FollowMode::Orbit,
            track: None,
            stale_after_s: DEFAULT_STALE_AFTER_S,
            now_s: f64::NEG_INFINITY,
            offset: None,
            leash_m: None,
            hold_down: 0.0,
            look_at: HoldPoint::default(),
            shaper: Shaper::default(),
        }
    }

    /// Set how old the last fix may be before the vehicle stops following (default
    /// [`DEFAULT_STALE_AFTER_S`]); nonsense is ignored.
    pub fn set_stale_after_s(&mut self, s: f64) {
        if s.is_finite() && s > 0.0 {
            self.stale_after_s = s;
        }
    }

    /// One phone position (from the UDP stream, newest per tick); `now_s` monotonic
    /// seconds. Filtered (alpha-beta) so jitter does not shake the vehicle; velocity
    /// estimated; fixes not newer than the last one, or with non-finite numbers,
    /// ignored.
    pub fn update_target(&mut self, p: GeoPoint, now_s: f64) {
        let finite = p.lat_deg.is_finite()
            && p.lon_deg.is_finite()
            && p.alt_rel_m.is_finite()
            && now_s.is_finite();
        if !finite {
            return;
        }
        self.now_s = self.now_s.max(now_s);
        let z = self.frame.to_ned(&p);
        match &mut self.track {
            Some(t) if now_s <= t.at_s => {}
            // A target lost for longer than the stale limit restarts the filter: its
            // old velocity says nothing about where it went.
            Some(t) if now_s - t.at_s <= self.stale_after_s => {
                let dt = now_s - t.at_s;
                let predicted = t.pos + t.vel * dt;
                let residual = z - predicted;
                // Fixed bandwidth whatever the fix rate; β from α (Benedict–Bordner)
                // for a well-damped velocity estimate.
                let alpha = 1.0 - (-dt / FILTER_TAU_S).exp();
                let beta = alpha * alpha / (2.0 - alpha);
                t.pos = predicted + residual * alpha;
                t.vel += residual * (beta / dt);
                t.at_s = now_s;
                t.fixes = t.fixes.saturating_add(1);
            }
            _ => {
                self.track = Some(Track {
                    pos: z,
                    vel: Vector3::zeros(),
                    at_s: now_s,
                    since_s: now_s,
                    fixes: 1,
                })
            }
        }
    }

    /// Change how the target is followed; the offset, leash and hold point are taken
    /// afresh from where the vehicle is at the next step with a target.
    pub fn set_mode(&mut self, mode: FollowMode, v: &VehicleView) {
        if mode == self.mode {
            return;
        }
        self.mode = mode;
        self.offset = None;
        self.leash_m = None;
        self.look_at.release();
        self.hold_down = self.frame.to_ned(&v.position).z;
    }

    /// The current follow style.
    pub fn mode(&self) -> FollowMode {
        self.mode
    }

    /// The filtered target, predicted to the latest time seen (the last step or
    /// fix, whichever is newer).
    pub fn target(&self) -> Option<GeoPoint> {
        self.target_at(self.now_s)
    }

    /// The filtered target predicted to `now_s` (no further than the stale limit).
    pub fn target_at(&self, now_s: f64) -> Option<GeoPoint> {
        self.predicted(now_s).map(|p| self.frame.to_geo(&p))
    }

    /// Estimated target velocity, NED m/s.
    pub fn target_velocity_ned(&self) -> [f32; 3] {
        self.track.map_or([0.0; 3], |t| to_f32(&t.vel))
    }

    /// The horizontal offset target → vehicle held in Orbit and FreeLook (north, east
    /// metres), once taken.
    pub fn offset_m(&self) -> Option<[f32; 2]> {
        self.offset.map(|o| [o.x as f32, o.y as f32])
    }

    /// Seconds since the last fix.
    pub fn target_age_s(&self, now_s: f64) -> Option<f64> {
        self.track.map(|t| (now_s - t.at_s).max(0.0))
    }

    fn predicted(&self, now_s: f64) -> Option<Vector3<f64>> {
        self.track.map(|t| {
            let ahead = now_s - t.at_s;
            let ahead = if ahead.is_finite() {
                ahead.clamp(0.0, self.stale_after_s)
            } else {
                0.0
            };
            t.pos + t.vel * ahead
        })
    }

    /// Follow for one tick. No target yet or target older than the stale limit →
    /// brake to a hover and `None` roi.
    pub fn step(
        &mut self,
        v: &VehicleView,
        now_s: f64,
        dt_s: f32,
        cruise_speed: f32,
        lim: &Limits,
    ) -> Guidance {
        let lim = Lim::new(lim);
        let dt = dt64(dt_s);
        if now_s.is_finite() {
            self.now_s = self.now_s.max(now_s);
        }
        let fresh = self
            .target_age_s(now_s)
            .is_some_and(|age| age <= self.stale_after_s);
        let (Some(target), Some(track), true) = (self.predicted(now_s), self.track, fresh) else {
            let vel = self.shaper.shape(Vector3::zeros(), v, dt_s, &lim);
            return Guidance {
                velocity_ned_mps: to_f32(&vel),
                ..Guidance::HOVER
            };
        };
        let roi = (self.mode != FollowMode::FreeLook).then(|| self.frame.to_geo(&target));
        if !track.warmed_up() && self.mode != FollowMode::LookAt {
            // The camera may look already; the vehicle waits for a settled target.
            let vel = self.shaper.shape(Vector3::zeros(), v, dt_s, &lim);
            return Guidance {
                velocity_ned_mps: to_f32(&vel),
                roi,
                ..Guidance::HOVER
            };
        }
        let pos = self.frame.to_ned(&v.position);
        let to_vehicle = Vector2::new(pos.x - target.x, pos.y - target.y);
        let target_vel = Vector2::new(track.vel.x, track.vel.y);
        let hold_z = sqrt_controller(self.hold_down - pos.z, lim.gain, lim.plan_accel(), dt);
        let commanded = self.shaper.current(v);

        let xy = match self.mode {
            FollowMode::Orbit | FollowMode::FreeLook => {
                let offset = *self
                    .offset
                    .get_or_insert_with(|| at_least(to_vehicle, MIN_FOLLOW_DISTANCE_M, v));
                let r = offset.norm();
                let cruise = if self.mode == FollowMode::Orbit && cruise_speed.is_finite() {
                    // Leave the vehicle the speed to keep up with the target too.
                    let spare = (lim.speed * SPEED_SHARE - target_vel.norm()).max(0.0);
                    let max = spare.min((lim.plan_accel() * r).sqrt());
                    f64::from(cruise_speed).clamp(-max, max)
                } else {
                    0.0
                };
                // Positive cruise is counter-clockwise seen from above: the angle
                // measured clockwise from north shrinks.
                let rate = -cruise / r;
                let offset = rotate(&offset, rate * dt);
                self.offset = Some(offset);
                let perp = Vector2::new(-offset.y, offset.x);
                let orbit_vel = perp * rate;
                let centripetal = -offset * (rate * rate);
                let err = (target.xy() + offset) - pos.xy();
                target_vel + orbit_vel + centripetal * VELOCITY_LAG_S + pull(err, &lim, dt)
            }
            FollowMode::Leash => {
                let leash = *self
                    .leash_m
                    .get_or_insert_with(|| to_vehicle.norm().max(MIN_FOLLOW_DISTANCE_M));
                let d = to_vehicle.norm();
                if d > 1e-6 {
                    let toward = -to_vehicle / d;
                    let taut = ((d - (leash - LEASH_TAKE_UP_M)) / LEASH_TAKE_UP_M).clamp(0.0, 1.0);
                    let away = target_vel.dot(&toward).max(0.0);
                    let catch_up =
                        sqrt_controller((d - leash).max(0.0), lim.gain, lim.plan_accel(), dt);
                    toward * (away * taut + catch_up)
                } else {
                    Vector2::zeros()
                }
            }
            FollowMode::LookAt => {
                let w = self.look_at.wish(&pos, &commanded, &lim, dt);
                Vector2::new(w.x, w.y)
            }
        };
        let z = if self.mode == FollowMode::LookAt {
            self.look_at.point().map_or(0.0, |p| {
                sqrt_controller(p.z - pos.z, lim.gain, lim.plan_accel(), dt)
            })
        } else {
            hold_z
        };
        let vel = self
            .shaper
            .shape(Vector3::new(xy.x, xy.y, z), v, dt_s, &lim);
        Guidance {
            velocity_ned_mps: to_f32(&vel),
            roi,
            yaw_deg: None,
            gimbal_pitch_deg: None,
        }
    }
}

/// Rotate a horizontal vector by `angle` radians clockwise seen from above.
fn rotate(v: &Vector2<f64>, angle: f64) -> Vector2<f64> {
    let (s, c) = angle.sin_cos();
    Vector2::new(v.x * c - v.y * s, v.x * s + v.y * c)
}

/// `v`, lengthened to at least `min` (behind the nose when `v` has no direction).
fn at_least(v: Vector2<f64>, min: f64, view: &VehicleView) -> Vector2<f64> {
    let n = v.norm();
    if n >= min {
        v
    } else if n > 1e-3 {
        v * (min / n)
    } else {
        let hd = f64::from(view.heading_deg).to_radians();
        let hd = if hd.is_finite() { hd } else { 0.0 };
        -Vector2::new(hd.cos(), hd.sin()) * min
    }
}

/// The correction for a horizontal position error: square-root profile, so a large
/// error is closed at a speed the vehicle can stop from.
fn pull(err: Vector2<f64>, lim: &Lim, dt: f64) -> Vector2<f64> {
    let d = err.norm();
    if d > 1e-9 {
        clamp_norm2(
            err * (sqrt_controller(d, lim.gain, lim.plan_accel(), dt) / d),
            lim.speed,
        )
    } else {
        Vector2::zeros()
    }
}
