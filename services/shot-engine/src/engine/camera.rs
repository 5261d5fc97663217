//! Camera commands from a shot's [`Guidance`]: sent only when they change
//! meaningfully, and not faster than 5 Hz while they keep changing.
//!
//! - ROI: `SetRoi` when it first appears, then when it has moved by more than
//!   [`ROI_MIN_CHANGE_M`] (at most every [`MIN_INTERVAL_NS`]); `ClearRoi` once when it
//!   goes away. While an ROI is set the autopilot points nose and gimbal at it, so no
//!   yaw or gimbal command is sent.
//! - Without an ROI: `SetYaw` / `Gimbal` (pitch, vehicle-relative yaw 0) when the
//!   requested angle first appears or changes by more than [`ANGLE_MIN_CHANGE_DEG`]
//!   (same rate limit). `None` leaves the camera to the pilot.

use skymesh_ipc_types::Command;

use crate::shots::{distance_m, GeoPoint, Guidance};

/// An ROI that moved less than this is not re-sent, m.
pub const ROI_MIN_CHANGE_M: f64 = 1.0;
/// A yaw or pitch that changed less than this is not re-sent, degrees.
pub const ANGLE_MIN_CHANGE_DEG: f32 = 1.0;
/// Camera commands of one kind are at most this frequent (5 Hz), ns.
pub const MIN_INTERVAL_NS: u64 = 200_000_000;

/// What was last commanded, and when.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Camera {
    pub roi: Option<GeoPoint>,
    roi_ns: u64,
    /// Send the ROI again on the next call even if it did not move.
    resend_roi: bool,
    yaw: Option<f32>,
    yaw_ns: u64,
    pitch: Option<f32>,
    pitch_ns: u64,
}

/// Smallest difference between two angles, degrees (0..=180).
pub fn angle_diff(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

fn set_roi(p: &GeoPoint) -> Command {
    Command::SetRoi {
        lat_deg: p.lat_deg,
        lon_deg: p.lon_deg,
        alt_rel_m: p.alt_rel_m,
    }
}

impl Camera {
    /// The autopilot may have forgotten what was sent (a mode change): send every
    /// requested camera command again on the next call. The ROI stays known as set,
    /// so an exit still clears it.
    pub fn resend(&mut self) {
        self.resend_roi = true;
        self.yaw = None;
        self.pitch = None;
    }

    /// Records an ROI commanded outside [`Camera::commands`] (when the flight starts).
    pub fn roi_sent(&mut self, roi: GeoPoint, now_ns: u64) -> Command {
        self.roi = Some(roi);
        self.roi_ns = now_ns;
        set_roi(&roi)
    }

    /// The camera commands `g` calls for at `now_ns`.
    pub fn commands(&mut self, g: &Guidance, now_ns: u64) -> Vec<Command> {
        let mut out = Vec::new();
        let due = |last_ns: u64| now_ns.saturating_sub(last_ns) >= MIN_INTERVAL_NS;
        let resend = std::mem::take(&mut self.resend_roi);
        match (g.roi, self.roi) {
            (Some(p), None) => out.push(self.roi_sent(p, now_ns)),
            (Some(p), Some(_)) if resend => out.push(self.roi_sent(p, now_ns)),
            (Some(p), Some(last)) => {
                if distance_m(&p, &last) > ROI_MIN_CHANGE_M && due(self.roi_ns) {
                    out.push(self.roi_sent(p, now_ns));
                }
            }
            (None, Some(_)) => {
                self.roi = None;
                // Angles must be sent afresh once the autopilot stops tracking the ROI.
                self.yaw = None;
                self.pitch = None;
                out.push(Command::ClearRoi);
            }
            (None, None) => {}
        }
        if g.roi.is_some() {
            return out;
        }
        if let Some(yaw) = g.yaw_deg.filter(|y| y.is_finite()) {
            let yaw = yaw.rem_euclid(360.0);
            let changed = self.yaw.is_none_or(|last| {
                angle_diff(yaw, last) > ANGLE_MIN_CHANGE_DEG && due(self.yaw_ns)
            });
            if changed {
                self.yaw = Some(yaw);
                self.yaw_ns = now_ns;
                out.push(Command::SetYaw {
                    yaw_deg: yaw,
                    rate_dps: 0.0,
                    relative: false,
                });
            }
        }
        if let Some(pitch) = g.gimbal_pitch_deg.filter(|p| p.is_finite()) {
            let pitch = pitch.clamp(-90.0, 30.0);
            let changed = self.pitch.is_none_or(|last| {
                (pitch - last).abs() > ANGLE_MIN_CHANGE_DEG && due(self.pitch_ns)
            });
            if changed {
                self.pitch = Some(pitch);
                self.pitch_ns = now_ns;
                out.push(Command::Gimbal {
                    pitch_deg: pitch,
                    yaw_deg: 0.0,
                });
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn roi(lat: f64) -> Guidance {
        Guidance {
            roi: Some(GeoPoint {
                lat_deg: lat,
                lon_deg: 149.0,
                alt_rel_m: 0.0,
            }),
            ..Guidance::HOVER
        }
    }

    #[test]
    fn roi_is_sent_on_change_at_most_at_5_hz_and_cleared_once() {
        let mut c = Camera::default();
        assert!(matches!(
            c.commands(&roi(-35.0), 0)[..],
            [Command::SetRoi { .. }]
        ));
        // 0.5 m: not re-sent.
        assert!(c
            .commands(&roi(-35.0 + 0.5 / 111_000.0), 300 * MS)
            .is_empty());
        // 5 m but within 200 ms of the last: not yet.
        assert!(c
            .commands(&roi(-35.0 + 5.0 / 111_000.0), 100 * MS)
            .is_empty());
        assert_eq!(c.commands(&roi(-35.0 + 5.0 / 111_000.0), 250 * MS).len(), 1);
        assert_eq!(c.commands(&Guidance::HOVER, 260 * MS), [Command::ClearRoi]);
        assert!(c.commands(&Guidance::HOVER, 600 * MS).is_empty());
    }

    #[test]
    fn yaw_and_pitch_follow_the_one_degree_rule() {
        let mut c = Camera::default();
        let g = |yaw: f32, pitch: f32| Guidance {
            yaw_deg: Some(yaw),
            gimbal_pitch_deg: Some(pitch),
            ..Guidance::HOVER
        };
        assert_eq!(c.commands(&g(359.5, -10.0), 0).len(), 2);
        // Across north, 1 degree apart: not a change.
        assert!(c.commands(&g(0.4, -10.5), 500 * MS).is_empty());
        let cmds = c.commands(&g(10.0, -30.0), 1000 * MS);
        assert_eq!(
            cmds,
            [
                Command::SetYaw {
                    yaw_deg: 10.0,
                    rate_dps: 0.0,
                    relative: false
                },
                Command::Gimbal {
                    pitch_deg: -30.0,
                    yaw_deg: 0.0
                }
            ]
        );
    }
}
