//! Pano (shot 7): hold position and turn the camera through a cylinder or sphere of
//! photos, or pan a video ([`crate::shots::pano`]).
//!
//! | from | setup | run |
//! |---|---|---|
//! | entry (SET_CURRENT_SHOT 7, a mapped button) | gate; flies at once (authority, GUIDED) holding position, camera the pilot's; SOLO_PANO_OPTIONS to the app | — |
//! | SOLO_PANO_OPTIONS | type, cylinder field of view, lens, video rate; runState 1 → run | video rate only; runState 0 (or 2) → back to setup |
//! | A | run | back to setup (cancel) |
//! | B | next type (video → sphere → cylinder → video; video rate 0), as the Solo cycles | — |
//! | Pause | video rate 0 ↔ the previous rate | same |
//!
//! Run: photo panos turn to each station and, once there and settled, send
//! `Command::CameraCapture` (payload authority) and SOLO_PANO_STATE (photos taken,
//! total; (0, total) when the run starts). After the last photo the shot ends as the
//! spec says ("exits to Fly"): SOLO_PANO_OPTIONS with runState 2 (the reference's
//! PANO_EXIT; the reference app reads anything but 1 as "not running"), then
//! GET_CURRENT_SHOT −1, brake and LOITER (exit reason `finished`). The video pan
//! turns at the rate until paused or the shot ends.
//!
//! The engine's cruise value for pano is the video pan rate, degrees per second
//! (positive clockwise, ±[`VIDEO_PAN_MAX_RATE_DPS`]), so pause works as in every
//! shot and `ShotStatus.cruise_speed_mps` carries it. Options are clamped as the
//! reference does: cylinder field of view 91..=360, lens 60..=180 degrees.
//! Where the reference differs: its A never starts a video pan (the video pans
//! whenever its rate is not 0); here A starts and stops every type alike.

use skymesh_ipc_types::shot_api::ShotEvent;
use skymesh_ipc_types::{Button, Command};

use super::shot::{Active, ShotKind};
use super::{Engine, ExitReason};
use crate::shots::pano::{DEFAULT_LENS_FOV_DEG, VIDEO_PAN_MAX_RATE_DPS};
use crate::shots::{
    Guidance, Limits, Pano, PanoKind, PanoOptions, PanoPhase, PanoStep, VehicleView,
};

/// The cylinder's field of view until the app sends one, degrees (the Solo's).
pub const DEFAULT_CYLINDER_FOV_DEG: f32 = 220.0;
/// The video pan's rate until the app sends one, degrees per second (the Solo's).
pub const DEFAULT_VIDEO_RATE_DPS: f32 = 2.0;
/// SOLO_PANO_OPTIONS runState when the pano finished (the reference's PANO_EXIT).
pub const RUN_STATE_FINISHED: u8 = 2;

/// The pano's own state.
#[derive(Debug)]
pub(crate) struct PanoShot {
    pub pano: Pano,
    /// The last step (read after the tick: photo trigger, finish).
    pub last: Option<PanoStep>,
    /// Photos reported with SOLO_PANO_STATE.
    reported: u8,
}

fn clamp_options(cylinder_fov: f32, lens_fov: f32) -> (f32, f32) {
    let fov = if cylinder_fov.is_finite() {
        cylinder_fov.clamp(91.0, 360.0)
    } else {
        360.0
    };
    let lens = if lens_fov.is_finite() {
        lens_fov.clamp(60.0, 180.0)
    } else {
        DEFAULT_LENS_FOV_DEG
    };
    (fov, lens)
}

/// The video rate as the engine keeps it (cruise), degrees per second.
fn clamp_rate(rate: f32) -> f32 {
    if rate.is_finite() {
        rate.clamp(-VIDEO_PAN_MAX_RATE_DPS, VIDEO_PAN_MAX_RATE_DPS)
    } else {
        0.0
    }
}

impl PanoShot {
    /// A cylinder pano in setup around `v` (the Solo's default type).
    pub fn new(v: &VehicleView) -> PanoShot {
        let options = PanoOptions {
            cylinder_fov_deg: DEFAULT_CYLINDER_FOV_DEG,
            lens_fov_deg: DEFAULT_LENS_FOV_DEG,
            yaw_rate_dps: DEFAULT_VIDEO_RATE_DPS,
        };
        PanoShot {
            pano: Pano::new(PanoKind::Cylinder, v, options),
            last: None,
            reported: 0,
        }
    }

    /// SOLO_PANO_OPTIONS as the engine uses them (`rate` = the cruise value).
    pub fn options(&self, rate: f32) -> ShotEvent {
        let o = self.pano.options();
        ShotEvent::PanoOptions {
            pano_type: self.pano.kind().to_wire(),
            run_state: match self.pano.phase() {
                PanoPhase::Setup => 0,
                PanoPhase::Run => 1,
                PanoPhase::Finished => RUN_STATE_FINISHED,
            },
            cylinder_fov: o.cylinder_fov_deg.round() as i16,
            deg_second_yaw: rate,
            lens_fov: o.lens_fov_deg,
        }
    }

    /// Photos taken / photos in total (0 for the video pan).
    pub fn progress(&self) -> f32 {
        let (taken, total) = self.pano.station();
        if total == 0 {
            0.0
        } else {
            f32::from(taken) / f32::from(total)
        }
    }

    /// This tick's guidance; the step is kept for [`Engine::pano_after_step`].
    pub fn guidance(
        &mut self,
        v: &VehicleView,
        now_ns: u64,
        dt: f32,
        rate: f32,
        lim: &Limits,
    ) -> Guidance {
        let o = self.pano.options();
        if o.yaw_rate_dps != rate {
            self.pano.set_options(PanoOptions {
                yaw_rate_dps: rate,
                ..o
            });
        }
        let step = self.pano.step(v, dt, now_ns as f64 / 1e9, lim);
        // A photo not yet handled stays due (a step never triggers twice in a row).
        let trigger = step.trigger || self.last.is_some_and(|l| l.trigger);
        self.last = Some(PanoStep { trigger, ..step });
        step.guidance
    }

    /// Back to setup with the same type and options (cancel, or a new type).
    fn reset(&mut self, kind: PanoKind, v: &VehicleView) {
        self.pano = Pano::new(kind, v, self.pano.options());
        self.last = None;
        self.reported = 0;
    }
}

fn pano_of(active: &mut Option<Active>) -> Option<&mut Active> {
    active
        .as_mut()
        .filter(|a| matches!(a.kind, ShotKind::Pano(_)))
}

impl Engine {
    /// Just entered: hold position.
    pub(crate) fn pano_start(&mut self, now_ns: u64) {
        if pano_of(&mut self.active).is_some() {
            tracing::info!("pano: setup, holding position");
            self.begin_flight(None, now_ns);
        }
    }

    fn pano_send_options(&mut self) {
        if let Some(Active {
            kind: ShotKind::Pano(p),
            cruise,
            ..
        }) = self.active.as_ref()
        {
            let msg = p.options(*cruise);
            self.out.app(msg);
        }
    }

    /// Setup → run (A, or runState 1).
    fn pano_run(&mut self, now_ns: u64) {
        let Some(v) = self.inputs.view(now_ns) else {
            self.out
                .error("pano: no vehicle position; the pano did not start");
            return;
        };
        let Some(Active {
            kind: ShotKind::Pano(p),
            ..
        }) = pano_of(&mut self.active)
        else {
            return;
        };
        if p.pano.phase() != PanoPhase::Setup {
            return;
        }
        p.pano.start(&v, now_ns as f64 / 1e9);
        p.last = None;
        p.reported = 0;
        let (_, total) = p.pano.station();
        tracing::info!(kind = ?p.pano.kind(), photos = total, "pano: run");
        if p.pano.kind() != PanoKind::VideoPan {
            self.out.app(ShotEvent::PanoState { index: 0, total });
        }
    }

    /// Run → setup (A again, or runState 0).
    fn pano_cancel(&mut self, now_ns: u64) {
        let Some(v) = self.inputs.view(now_ns) else {
            return;
        };
        if let Some(Active {
            kind: ShotKind::Pano(p),
            ..
        }) = pano_of(&mut self.active)
        {
            if p.pano.phase() != PanoPhase::Setup {
                let kind = p.pano.kind();
                p.reset(kind, &v);
                tracing::info!("pano: cancelled, back to setup");
            }
        }
    }

    /// SOLO_PANO_OPTIONS from the app.
    pub(crate) fn pano_options(
        &mut self,
        pano_type: u8,
        run_state: u8,
        cylinder_fov: i16,
        deg_second_yaw: f32,
        lens_fov: f32,
        now_ns: u64,
    ) {
        let view = self.inputs.view(now_ns);
        let Some(a) = pano_of(&mut self.active) else {
            tracing::debug!("PANO_OPTIONS outside pano ignored");
            return;
        };
        let ShotKind::Pano(p) = &mut a.kind else {
            return;
        };
        let (fov, lens) = clamp_options(f32::from(cylinder_fov), lens_fov);
        a.cruise = clamp_rate(deg_second_yaw);
        a.paused = None;
        let options = PanoOptions {
            cylinder_fov_deg: fov,
            lens_fov_deg: lens,
            yaw_rate_dps: a.cruise,
        };
        let setup = p.pano.phase() == PanoPhase::Setup;
        let kind = PanoKind::from_wire(pano_type).unwrap_or(p.pano.kind());
        if setup {
            p.pano.set_options(options);
            if kind != p.pano.kind() {
                if let Some(v) = view.as_ref() {
                    p.reset(kind, v);
                }
            }
        }
        tracing::info!(
            pano_type,
            run_state,
            cylinder_fov = fov,
            lens_fov = lens,
            rate = a.cruise,
            "pano: options"
        );
        match (run_state, setup) {
            (1, true) => self.pano_run(now_ns),
            (0 | RUN_STATE_FINISHED, false) => self.pano_cancel(now_ns),
            _ => {}
        }
    }

    /// A or B in pano.
    pub(crate) fn pano_button(&mut self, button: Button, now_ns: u64) {
        let Some(a) = pano_of(&mut self.active) else {
            return;
        };
        let ShotKind::Pano(p) = &mut a.kind else {
            return;
        };
        let setup = p.pano.phase() == PanoPhase::Setup;
        match button {
            Button::A if setup => self.pano_run(now_ns),
            Button::A => self.pano_cancel(now_ns),
            Button::B if setup => {
                let Some(v) = self.inputs.view(now_ns) else {
                    return;
                };
                let next = match p.pano.kind() {
                    PanoKind::VideoPan => PanoKind::Sphere,
                    PanoKind::Sphere => PanoKind::Cylinder,
                    PanoKind::Cylinder => PanoKind::VideoPan,
                };
                p.reset(next, &v);
                a.cruise = 0.0;
                a.paused = None;
                tracing::info!(kind = ?next, "pano: type");
            }
            _ => {
                tracing::info!(%button, "pano: button does nothing now");
                return;
            }
        }
        self.pano_send_options();
    }

    /// After a tick: the photo the step asked for, and the end of a photo pano.
    pub(crate) fn pano_after_step(&mut self) {
        let Some(Active {
            kind: ShotKind::Pano(p),
            ..
        }) = self.active.as_mut()
        else {
            return;
        };
        let Some(step) = p.last.as_mut() else {
            return;
        };
        let trigger = std::mem::take(&mut step.trigger);
        let (taken, total) = step.station;
        let finished = step.phase == PanoPhase::Finished;
        let report = taken > p.reported;
        if report {
            p.reported = taken;
        }
        if trigger {
            tracing::info!(photo = taken, of = total, "pano: photo");
            self.payload_used = true;
            self.out.command(Command::CameraCapture);
        }
        if report {
            self.out.app(ShotEvent::PanoState {
                index: taken,
                total,
            });
        }
        if finished {
            tracing::info!(photos = total, "pano: finished");
            self.pano_send_options();
            self.exit_shot(ExitReason::Finished);
        }
    }
}
