//! Tracking and scoring (DigiView DETECTION).
//!
//! One [`Tracker::update`] per frame, in this order:
//!
//! 1. **Scan hits**: hits below `scan_confidence` are ignored; the rest are
//!    suppressed greedily by confidence (NMS): a hit overlapping a kept one by more
//!    than `scan_overlap` (IoU) is dropped.
//! 2. **Matching**: every (track, hit) pair that overlaps (IoU ≥ [`MATCH_MIN_IOU`])
//!    or whose centres are closer than the track box's larger side gets a match
//!    quality (the IoU, or a small value falling with the centre distance); pairs
//!    are taken greedily, best first, each track and hit at most once.
//! 3. **Scores** (all arithmetic on the sum, saturated to 0..=254 once):
//!    - a track the scan found: `+ bonus_detection`;
//!    - a track the scan did not find: `− missed_detection_penalty` (it was expected
//!      to be found when scanning), and then the track model looks for it near its
//!      last box ([`Tracker::update`]'s `verify`): found with confidence ≥
//!      `track_confidence` → `+ bonus_redetection` (and its box moves there), else
//!      `− missed_redetection_penalty`.
//!
//!    So a track lost by both loses both penalties each frame; one only the track
//!    model still finds nets `bonus_redetection − missed_detection_penalty`.
//!    A track whose score reaches 0 is deleted.
//! 4. **New objects**: every unmatched hit starts a track at `creation_score` (none
//!    when that is 0) with the next free id.
//! 5. **Overlaps**: of two tracks overlapping by more than `track_overlap` (IoU),
//!    the one with the lower score is deleted (equal scores: the younger one).
//! 6. **Order** by the sorting mode: 0 score (desc), 1 age (desc), 2 score (desc)
//!    with overlay slots locked for life ([`Tracker::assign_overlay`]). Ties: the
//!    other key, then the lower id.
//!
//! Ids are 0..=253, never two alive at once; a new object takes the first free id
//! after the last one given (wrapping), so an id does not come straight back for a
//! different object. With 254 objects alive new hits are dropped.

use crate::detect::{PixelBox, RawDetection};

/// The largest id (254 and 255 mean "none" / "all" on the wire).
pub const MAX_ID: u8 = 253;
/// Pairs overlapping at least this much are matched by overlap.
pub const MATCH_MIN_IOU: f32 = 0.1;

/// DETECTION's parameters (thresholds and overlaps 0..0.99, scores 0–254).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerParams {
    pub sorting_mode: u8,
    pub track_confidence: f32,
    pub scan_confidence: f32,
    pub track_overlap: f32,
    pub scan_overlap: f32,
    pub creation_score: u8,
    pub bonus_detection: u8,
    pub bonus_redetection: u8,
    pub missed_detection_penalty: u8,
    pub missed_redetection_penalty: u8,
}

impl Default for TrackerParams {
    fn default() -> Self {
        TrackerParams {
            sorting_mode: 0,
            track_confidence: 0.3,
            scan_confidence: 0.5,
            track_overlap: 0.5,
            scan_overlap: 0.3,
            creation_score: 60,
            bonus_detection: 20,
            bonus_redetection: 10,
            missed_detection_penalty: 10,
            missed_redetection_penalty: 20,
        }
    }
}

/// One tracked object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Track {
    /// Stable for the object's lifetime, 0–253.
    pub id: u8,
    /// 0–254; the object is dropped when it reaches 0.
    pub score: u8,
    pub age_frames: u32,
    pub bbox: PixelBox,
    pub confidence: f32,
    pub model: u8,
    /// Detection tile (overlay slot) showing it.
    pub overlay_slot: Option<u8>,
    /// Found (by scan or verify) in the last update.
    pub seen: bool,
}

/// The tracker.
#[derive(Debug)]
pub struct Tracker {
    params: TrackerParams,
    tracks: Vec<Track>,
    /// The id given last (the next search starts after it).
    last_id: u8,
}

impl Tracker {
    pub fn new(params: TrackerParams) -> Tracker {
        Tracker {
            params,
            tracks: Vec::new(),
            last_id: MAX_ID,
        }
    }
    pub fn params(&self) -> &TrackerParams {
        &self.params
    }
    /// New parameters (the caller has validated them; an unknown sorting mode keeps
    /// the current one). Re-sorts; leaving mode 2 unlocks the overlay slots at the
    /// next [`Tracker::assign_overlay`].
    pub fn set_params(&mut self, params: TrackerParams) {
        let mode = if params.sorting_mode <= 2 {
            params.sorting_mode
        } else {
            self.params.sorting_mode
        };
        self.params = TrackerParams {
            sorting_mode: mode,
            ..params
        };
        self.sort();
    }
    /// One frame: `scan` are the scan model's hits; `verify` asks the track model to
    /// look for an object near its last box.
    pub fn update(
        &mut self,
        scan: &[RawDetection],
        verify: &mut dyn FnMut(&PixelBox) -> Option<RawDetection>,
    ) {
        let p = self.params;
        let hits = suppress(scan, p.scan_confidence, p.scan_overlap);

        // Matching, greedy by quality.
        let mut pairs = Vec::new();
        for (ti, t) in self.tracks.iter().enumerate() {
            for (hi, h) in hits.iter().enumerate() {
                let q = match_quality(&t.bbox, &h.bbox);
                if q > 0.0 {
                    pairs.push((q, ti, hi));
                }
            }
        }
        pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut track_hit: Vec<Option<usize>> = vec![None; self.tracks.len()];
        let mut hit_used = vec![false; hits.len()];
        for (_, ti, hi) in pairs {
            if track_hit[ti].is_none() && !hit_used[hi] {
                track_hit[ti] = Some(hi);
                hit_used[hi] = true;
            }
        }

        // Scores.
        for (t, m) in self.tracks.iter_mut().zip(&track_hit) {
            t.age_frames = t.age_frames.saturating_add(1);
            let mut score = i32::from(t.score);
            match m {
                Some(hi) => {
                    let h = &hits[*hi];
                    score += i32::from(p.bonus_detection);
                    t.bbox = h.bbox;
                    t.confidence = h.confidence;
                    t.model = h.model;
                    t.seen = true;
                }
                None => {
                    score -= i32::from(p.missed_detection_penalty);
                    match verify(&t.bbox).filter(|d| d.confidence >= p.track_confidence) {
                        Some(d) => {
                            score += i32::from(p.bonus_redetection);
                            t.bbox = d.bbox;
                            t.confidence = d.confidence;
                            t.model = d.model;
                            t.seen = true;
                        }
                        None => {
                            score -= i32::from(p.missed_redetection_penalty);
                            t.seen = false;
                        }
                    }
                }
            }
            t.score = score.clamp(0, 254) as u8;
        }
        self.tracks.retain(|t| t.score > 0);

        // New objects.
        if p.creation_score > 0 {
            for (h, _) in hits.iter().zip(&hit_used).filter(|(_, used)| !**used) {
                let Some(id) = self.next_id() else { break };
                self.tracks.push(Track {
                    id,
                    score: p.creation_score.min(254),
                    age_frames: 0,
                    bbox: h.bbox,
                    confidence: h.confidence,
                    model: h.model,
                    overlay_slot: None,
                    seen: true,
                });
            }
        }

        self.resolve_overlaps();
        self.sort();
    }
    /// The objects, in the sorting mode's order (best first).
    pub fn tracks(&self) -> &[Track] {
        &self.tracks
    }
    pub fn get(&self, id: u8) -> Option<&Track> {
        self.tracks.iter().find(|t| t.id == id)
    }
    /// Gives the first `slots` objects (sorting mode order; mode 2 keeps a slot for the
    /// object's lifetime) a detection tile each.
    pub fn assign_overlay(&mut self, slots: usize) {
        let slots = slots.min(usize::from(u8::MAX));
        if self.params.sorting_mode == 2 {
            // Locked: keep every slot still shown; free slots go to the best unslotted.
            for t in &mut self.tracks {
                if t.overlay_slot.is_some_and(|s| usize::from(s) >= slots) {
                    t.overlay_slot = None;
                }
            }
            let mut used = vec![false; slots];
            for t in &self.tracks {
                if let Some(s) = t.overlay_slot {
                    used[usize::from(s)] = true;
                }
            }
            let mut free = (0..slots).filter(|&s| !used[s]);
            for t in &mut self.tracks {
                if t.overlay_slot.is_none() {
                    match free.next() {
                        Some(s) => t.overlay_slot = Some(s as u8),
                        None => break,
                    }
                }
            }
        } else {
            for (i, t) in self.tracks.iter_mut().enumerate() {
                t.overlay_slot = (i < slots).then_some(i as u8);
            }
        }
    }
    /// Forgets every object (AI disabled). Ids continue after the last one given.
    pub fn clear(&mut self) {
        self.tracks.clear();
    }

    /// The first free id after the last one given, wrapping in 0..=253.
    fn next_id(&mut self) -> Option<u8> {
        let mut used = [false; MAX_ID as usize + 1];
        for t in &self.tracks {
            used[usize::from(t.id)] = true;
        }
        let n = u16::from(MAX_ID) + 1;
        for k in 1..=n {
            let id = ((u16::from(self.last_id) + k) % n) as u8;
            if !used[usize::from(id)] {
                self.last_id = id;
                return Some(id);
            }
        }
        None
    }

    fn resolve_overlaps(&mut self) {
        let limit = self.params.track_overlap;
        // Best first (score, then age), so the first of an overlapping pair survives.
        self.tracks.sort_by(|a, b| {
            b.score
                .cmp(&a.score)
                .then(b.age_frames.cmp(&a.age_frames))
                .then(a.id.cmp(&b.id))
        });
        let mut keep: Vec<Track> = Vec::with_capacity(self.tracks.len());
        for t in self.tracks.drain(..) {
            if keep.iter().all(|k| k.bbox.iou(&t.bbox) <= limit) {
                keep.push(t);
            }
        }
        self.tracks = keep;
    }

    fn sort(&mut self) {
        let by_age = self.params.sorting_mode == 1;
        self.tracks.sort_by(|a, b| {
            let (score, age) = (b.score.cmp(&a.score), b.age_frames.cmp(&a.age_frames));
            let first = if by_age {
                age.then(score)
            } else {
                score.then(age)
            };
            first.then(a.id.cmp(&b.id))
        });
    }
}

/// Hits at or above `min_confidence`, greedily by confidence, dropping any that
/// overlaps a kept one by more than `max_overlap`.
fn suppress(scan: &[RawDetection], min_confidence: f32, max_overlap: f32) -> Vec<RawDetection> {
    let mut sorted: Vec<RawDetection> = scan
        .iter()
        .filter(|d| d.confidence >= min_confidence && d.confidence.is_finite())
        .copied()
        .collect();
    sorted.sort_by(|a, b| b.confidence.total_cmp(&a.confidence));
    let mut kept: Vec<RawDetection> = Vec::with_capacity(sorted.len());
    for d in sorted {
        if kept.iter().all(|k| k.bbox.iou(&d.bbox) <= max_overlap) {
            kept.push(d);
        }
    }
    kept
}

/// Overlap first (IoU ≥ [`MATCH_MIN_IOU`]); else centres closer than the track box's
/// larger side give a small quality falling with the distance; else 0.
fn match_quality(track: &PixelBox, hit: &PixelBox) -> f32 {
    let iou = track.iou(hit);
    if iou >= MATCH_MIN_IOU {
        return iou;
    }
    let (a, b) = (track.center(), hit.center());
    let d = (a.0 - b.0).hypot(a.1 - b.1);
    let reach = track.w.max(track.h);
    if reach > 0.0 && d < reach {
        MATCH_MIN_IOU * (1.0 - d / reach)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(x: f32, y: f32, side: f32, confidence: f32) -> RawDetection {
        RawDetection {
            bbox: PixelBox {
                x,
                y,
                w: side,
                h: side,
            },
            confidence,
            model: 0,
        }
    }

    fn none(_: &PixelBox) -> Option<RawDetection> {
        None
    }

    #[test]
    fn creation_and_detection_bonus() {
        let mut t = Tracker::new(TrackerParams::default());
        t.update(&[det(10.0, 10.0, 20.0, 0.9)], &mut none);
        assert_eq!(t.tracks().len(), 1);
        let first = t.tracks()[0];
        assert_eq!(first.score, 60);
        assert_eq!(first.age_frames, 0);
        assert!(first.seen);
        // Moved a little: matched, +20, same id, box follows.
        t.update(&[det(14.0, 12.0, 20.0, 0.8)], &mut none);
        let tr = t.tracks()[0];
        assert_eq!((tr.id, tr.score, tr.age_frames), (first.id, 80, 1));
        assert_eq!(tr.bbox.x, 14.0);
        // Saturates at 254.
        for _ in 0..20 {
            t.update(&[det(14.0, 12.0, 20.0, 0.8)], &mut none);
        }
        assert_eq!(t.tracks()[0].score, 254);
    }

    #[test]
    fn low_confidence_hits_are_ignored_and_zero_creation_creates_nothing() {
        let mut t = Tracker::new(TrackerParams::default());
        t.update(&[det(10.0, 10.0, 20.0, 0.4)], &mut none);
        assert!(t.tracks().is_empty());
        t.set_params(TrackerParams {
            creation_score: 0,
            ..TrackerParams::default()
        });
        t.update(&[det(10.0, 10.0, 20.0, 0.9)], &mut none);
        assert!(t.tracks().is_empty());
    }

    #[test]
    fn both_penalties_and_redetection_bonus() {
        let mut t = Tracker::new(TrackerParams::default());
        t.update(&[det(10.0, 10.0, 20.0, 0.9)], &mut none);
        // Scan misses it, the track model finds it: −10 + 10.
        let mut calls = 0;
        let mut found = |b: &PixelBox| {
            calls += 1;
            Some(RawDetection {
                bbox: PixelBox { x: b.x + 2.0, ..*b },
                confidence: 0.35,
                model: 1,
            })
        };
        t.update(&[], &mut found);
        assert_eq!(calls, 1);
        let tr = t.tracks()[0];
        assert_eq!((tr.score, tr.seen, tr.model), (60, true, 1));
        assert_eq!(tr.bbox.x, 12.0);
        // The track model finds it below track_confidence: missed both, −10 − 20.
        let mut weak = |b: &PixelBox| {
            Some(RawDetection {
                bbox: *b,
                confidence: 0.2,
                model: 1,
            })
        };
        t.update(&[], &mut weak);
        let tr = t.tracks()[0];
        assert_eq!((tr.score, tr.seen), (30, false));
        // Only the redetection penalty when the scan penalty is 0.
        t.set_params(TrackerParams {
            missed_detection_penalty: 0,
            ..TrackerParams::default()
        });
        t.update(&[], &mut none);
        assert_eq!(t.tracks()[0].score, 10);
        // Deleted at 0.
        t.update(&[], &mut none);
        assert!(t.tracks().is_empty());
    }

    #[test]
    fn scan_penalty_alone() {
        let mut t = Tracker::new(TrackerParams {
            missed_redetection_penalty: 0,
            bonus_redetection: 0,
            ..TrackerParams::default()
        });
        t.update(&[det(10.0, 10.0, 20.0, 0.9)], &mut none);
        t.update(&[], &mut none);
        assert_eq!(t.tracks()[0].score, 50);
        // A matched track is not verified.
        let mut never = |_: &PixelBox| -> Option<RawDetection> { panic!("verify called") };
        t.update(&[det(10.0, 10.0, 20.0, 0.9)], &mut never);
        assert_eq!(t.tracks()[0].score, 70);
    }

    #[test]
    fn ids_are_stable_and_not_reused_at_once() {
        let mut t = Tracker::new(TrackerParams::default());
        t.update(
            &[det(0.0, 0.0, 10.0, 0.9), det(100.0, 0.0, 10.0, 0.9)],
            &mut none,
        );
        let mut ids: Vec<u8> = t.tracks().iter().map(|x| x.id).collect();
        ids.sort();
        assert_eq!(ids, vec![0, 1]);
        // Object 0 goes away (60 − 30 − 30 = 0 after two frames); object 1 stays.
        for _ in 0..2 {
            t.update(&[det(100.0, 0.0, 10.0, 0.9)], &mut none);
        }
        assert!(t.get(0).is_none());
        assert_eq!(t.get(1).unwrap().bbox.x, 100.0);
        // A new object gets 2, not the freed 0.
        t.update(
            &[det(100.0, 0.0, 10.0, 0.9), det(0.0, 0.0, 10.0, 0.9)],
            &mut none,
        );
        assert_eq!(t.get(1).unwrap().bbox.x, 100.0);
        assert_eq!(t.get(2).unwrap().bbox.x, 0.0);
        // Wraps after 253 and skips live ids.
        let mut t = Tracker::new(TrackerParams::default());
        t.last_id = 252;
        t.update(&[det(0.0, 0.0, 10.0, 0.9)], &mut none);
        t.update(
            &[det(0.0, 0.0, 10.0, 0.9), det(50.0, 0.0, 10.0, 0.9)],
            &mut none,
        );
        t.update(
            &[
                det(0.0, 0.0, 10.0, 0.9),
                det(50.0, 0.0, 10.0, 0.9),
                det(100.0, 0.0, 10.0, 0.9),
            ],
            &mut none,
        );
        let mut ids: Vec<u8> = t.tracks().iter().map(|x| x.id).collect();
        ids.sort();
        assert_eq!(ids, vec![0, 1, 253]);
    }

    #[test]
    fn all_ids_in_use_drops_new_hits() {
        let mut t = Tracker::new(TrackerParams::default());
        let hits: Vec<RawDetection> = (0..300)
            .map(|i| det((i % 20) as f32 * 30.0, (i / 20) as f32 * 30.0, 10.0, 0.9))
            .collect();
        t.update(&hits, &mut none);
        assert_eq!(t.tracks().len(), 254);
        let mut ids: Vec<u8> = t.tracks().iter().map(|x| x.id).collect();
        ids.sort();
        ids.dedup();
        assert_eq!(ids.len(), 254);
        assert!(ids.iter().all(|&i| i <= MAX_ID));
    }

    #[test]
    fn nms_suppresses_overlapping_scan_hits() {
        let mut t = Tracker::new(TrackerParams::default());
        // IoU of these two is 0.6 > 0.3: only the more confident one survives.
        t.update(
            &[det(0.0, 0.0, 20.0, 0.7), det(5.0, 0.0, 20.0, 0.9)],
            &mut none,
        );
        assert_eq!(t.tracks().len(), 1);
        assert_eq!(t.tracks()[0].bbox.x, 5.0);
        // With scan_overlap 0.7 both are kept, but track_overlap 0.5 merges them.
        let mut t = Tracker::new(TrackerParams {
            scan_overlap: 0.7,
            ..TrackerParams::default()
        });
        t.update(
            &[det(0.0, 0.0, 20.0, 0.7), det(5.0, 0.0, 20.0, 0.9)],
            &mut none,
        );
        assert_eq!(t.tracks().len(), 1);
        t.set_params(TrackerParams {
            scan_overlap: 0.7,
            track_overlap: 0.9,
            ..TrackerParams::default()
        });
        t.update(
            &[
                det(0.0, 0.0, 20.0, 0.7),
                det(5.0, 0.0, 20.0, 0.9),
                det(200.0, 0.0, 20.0, 0.9),
            ],
            &mut none,
        );
        assert_eq!(t.tracks().len(), 3);
    }

    #[test]
    fn overlapping_tracks_keep_the_higher_score() {
        let mut t = Tracker::new(TrackerParams::default());
        t.update(&[det(0.0, 0.0, 20.0, 0.9)], &mut none);
        t.update(&[det(0.0, 0.0, 20.0, 0.9)], &mut none); // score 80
        let old = t.tracks()[0].id;
        // A second hit: the first matches the old track, the second (overlapping it by
        // IoU 0.6 after the first update) is created at 60 and loses.
        t.set_params(TrackerParams {
            scan_overlap: 0.9,
            ..TrackerParams::default()
        });
        t.update(
            &[det(0.0, 0.0, 20.0, 0.9), det(5.0, 0.0, 20.0, 0.8)],
            &mut none,
        );
        assert_eq!(t.tracks().len(), 1);
        assert_eq!(t.tracks()[0].id, old);
        assert_eq!(t.tracks()[0].score, 100);
    }

    #[test]
    fn sorting_modes() {
        let mut t = Tracker::new(TrackerParams::default());
        // A old, then B; B gets more hits so a higher score, A stays older.
        t.update(&[det(0.0, 0.0, 10.0, 0.9)], &mut none);
        let a = t.tracks()[0].id;
        let found = |b: &PixelBox| {
            Some(RawDetection {
                bbox: *b,
                confidence: 0.9,
                model: 0,
            })
        };
        t.update(&[det(100.0, 0.0, 10.0, 0.9)], &mut { found });
        let b = t.get(a.wrapping_add(1)).unwrap().id;
        for _ in 0..3 {
            t.update(&[det(100.0, 0.0, 10.0, 0.9)], &mut { found });
        }
        // A: 60 + 4×(−10+10) = 60, age 4; B: 60 + 3×20 = 120, age 3.
        assert_eq!(t.get(a).unwrap().score, 60);
        assert_eq!(t.get(b).unwrap().score, 120);
        let order = |t: &Tracker| t.tracks().iter().map(|x| x.id).collect::<Vec<_>>();
        assert_eq!(order(&t), vec![b, a]);
        t.set_params(TrackerParams {
            sorting_mode: 1,
            ..TrackerParams::default()
        });
        assert_eq!(order(&t), vec![a, b]);
        // Out-of-range mode keeps the current one.
        t.set_params(TrackerParams {
            sorting_mode: 7,
            ..TrackerParams::default()
        });
        assert_eq!(t.params().sorting_mode, 1);
        t.assign_overlay(1);
        assert_eq!(t.get(a).unwrap().overlay_slot, Some(0));
        assert_eq!(t.get(b).unwrap().overlay_slot, None);
    }

    #[test]
    fn mode_two_locks_overlay_slots_for_life() {
        let mut t = Tracker::new(TrackerParams {
            sorting_mode: 2,
            ..TrackerParams::default()
        });
        let found = |b: &PixelBox| {
            Some(RawDetection {
                bbox: *b,
                confidence: 0.9,
                model: 0,
            })
        };
        t.update(&[det(0.0, 0.0, 10.0, 0.9)], &mut { found });
        let a = t.tracks()[0].id;
        t.assign_overlay(1);
        assert_eq!(t.get(a).unwrap().overlay_slot, Some(0));
        // B arrives and scores higher than A; A keeps the only slot.
        for _ in 0..3 {
            t.update(&[det(100.0, 0.0, 10.0, 0.9)], &mut { found });
            t.assign_overlay(1);
        }
        let b = t.tracks()[0].id;
        assert_ne!(a, b);
        assert!(t.get(b).unwrap().score > t.get(a).unwrap().score);
        assert_eq!(t.get(a).unwrap().overlay_slot, Some(0));
        assert_eq!(t.get(b).unwrap().overlay_slot, None);
        // Mode 0 would give it to B.
        t.set_params(TrackerParams::default());
        t.assign_overlay(1);
        assert_eq!(t.get(b).unwrap().overlay_slot, Some(0));
        assert_eq!(t.get(a).unwrap().overlay_slot, None);
        // Back in mode 2: when A dies, its slot goes to the best remaining.
        let mut t2 = Tracker::new(TrackerParams {
            sorting_mode: 2,
            ..TrackerParams::default()
        });
        t2.update(&[det(0.0, 0.0, 10.0, 0.9)], &mut none);
        t2.assign_overlay(1);
        let a = t2.tracks()[0].id;
        t2.update(&[det(100.0, 0.0, 10.0, 0.9)], &mut none);
        t2.assign_overlay(1);
        assert_eq!(t2.get(a).unwrap().overlay_slot, Some(0));
        t2.update(&[det(100.0, 0.0, 10.0, 0.9)], &mut none);
        t2.assign_overlay(1);
        assert!(t2.get(a).is_none());
        assert_eq!(t2.tracks()[0].overlay_slot, Some(0));
        // Fewer slots drop the ones past the end.
        t2.assign_overlay(0);
        assert_eq!(t2.tracks()[0].overlay_slot, None);
    }

    #[test]
    fn clear_forgets_but_ids_continue() {
        let mut t = Tracker::new(TrackerParams::default());
        t.update(&[det(0.0, 0.0, 10.0, 0.9)], &mut none);
        t.clear();
        assert!(t.tracks().is_empty());
        t.update(&[det(0.0, 0.0, 10.0, 0.9)], &mut none);
        assert_eq!(t.tracks()[0].id, 1);
    }
}
