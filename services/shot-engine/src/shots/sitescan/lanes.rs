//! Survey lanes: the pieces of lanes over a polygon, and the order they are flown
//! in (see the contract in `sitescan.rs`). Worked on as (along, offset) metres in the
//! lanes' own frame.

use nalgebra::Vector2;

use super::{SiteScanError, MAX_SURVEY_LANES};

/// Heading (radians from north) of the ring's longest edge.
pub(super) fn longest_edge_heading(ring: &[Vector2<f64>]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|i| ring[(i + 1) % n] - ring[i])
        .max_by(|a, b| a.norm().total_cmp(&b.norm()))
        .map_or(0.0, |d| d.y.atan2(d.x))
}

/// A lane piece: across offset, along start, along end (start < end).
pub(super) type Segment = (f64, f64, f64);

/// The lane pieces over `ring` with lanes along `heading` (radians) `spacing`
/// apart: each lane covers the polygon within ± spacing/2 of it (module doc), or,
/// `within`, is its own line clipped to the polygon.
pub(super) fn lane_segments(
    ring: &[Vector2<f64>],
    heading: f64,
    spacing: f64,
    within: bool,
) -> Result<Vec<Segment>, SiteScanError> {
    let u = Vector2::new(heading.cos(), heading.sin());
    let w = Vector2::new(-heading.sin(), heading.cos());
    // (along, offset) of each vertex.
    let pts: Vec<(f64, f64)> = ring.iter().map(|p| (p.dot(&u), p.dot(&w))).collect();
    let (lo, hi) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |m, p| {
        (m.0.min(p.1), m.1.max(p.1))
    });
    let n_lanes = ((hi - lo) / spacing).ceil().max(1.0);
    if n_lanes > MAX_SURVEY_LANES as f64 {
        return Err(SiteScanError::TooLarge {
            what: "lanes",
            count: n_lanes.min(usize::MAX as f64) as usize,
            max: MAX_SURVEY_LANES,
        });
    }
    let n_lanes = n_lanes as usize;
    let mid = (lo + hi) / 2.0;
    let first = mid - (n_lanes as f64 - 1.0) * spacing / 2.0;
    let mut out = Vec::new();
    for j in 0..n_lanes {
        let c = first + j as f64 * spacing;
        let (s_lo, s_hi) = ((c - spacing / 2.0).max(lo), (c + spacing / 2.0).min(hi));
        let pieces = if within {
            line_intervals(&pts, c)
        } else {
            strip_intervals(&pts, s_lo, s_hi)
        };
        for (a, b) in pieces {
            out.push((c, a, b));
        }
        if out.len() > MAX_SURVEY_LANES {
            return Err(SiteScanError::TooLarge {
                what: "lanes",
                count: out.len(),
                max: MAX_SURVEY_LANES,
            });
        }
    }
    Ok(out)
}

/// The along-extents of the polygon (vertices as (along, offset)) within the strip
/// of offsets `lo..=hi`: the strip is cut at every vertex offset into slices no
/// vertex is inside; in each slice the polygon is trapezoids between pairs of edges
/// crossing it, whose along-extents are merged where they overlap.
fn strip_intervals(pts: &[(f64, f64)], lo: f64, hi: f64) -> Vec<(f64, f64)> {
    let n = pts.len();
    let mut cuts: Vec<f64> = vec![lo, hi];
    cuts.extend(pts.iter().map(|p| p.1).filter(|&o| o > lo && o < hi));
    cuts.sort_by(f64::total_cmp);
    cuts.dedup();
    let mut pieces: Vec<(f64, f64)> = Vec::new();
    for s in cuts.windows(2) {
        let (o1, o2) = (s[0], s[1]);
        if o2 - o1 < 1e-9 {
            continue;
        }
        let m = (o1 + o2) / 2.0;
        // Edges crossing the slice, as (along at o1, along at o2).
        let mut crossing: Vec<(f64, f64)> = (0..n)
            .filter_map(|i| {
                let (a, b) = (pts[i], pts[(i + 1) % n]);
                let (mn, mx) = (a.1.min(b.1), a.1.max(b.1));
                if mn < m && m < mx {
                    let at = |o: f64| a.0 + (b.0 - a.0) * (o - a.1) / (b.1 - a.1);
                    Some((at(o1), at(o2)))
                } else {
                    None
                }
            })
            .collect();
        crossing.sort_by(|x, y| (x.0 + x.1).total_cmp(&(y.0 + y.1)));
        for pair in crossing.chunks_exact(2) {
            let (e1, e2) = (pair[0], pair[1]);
            let a = e1.0.min(e1.1).min(e2.0).min(e2.1);
            let b = e1.0.max(e1.1).max(e2.0).max(e2.1);
            pieces.push((a, b));
        }
    }
    pieces.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut merged: Vec<(f64, f64)> = Vec::new();
    for p in pieces {
        match merged.last_mut() {
            Some(last) if p.0 <= last.1 + 1e-6 => last.1 = last.1.max(p.1),
            _ => merged.push(p),
        }
    }
    merged
}

/// The along-extents of the polygon (vertices as (along, offset)) on the line at
/// offset `c` (an edge counts from its lower end up to, not including, its upper
/// one, so a line through a vertex is crossed once).
fn line_intervals(pts: &[(f64, f64)], c: f64) -> Vec<(f64, f64)> {
    let n = pts.len();
    let mut xs: Vec<f64> = (0..n)
        .filter_map(|i| {
            let (a, b) = (pts[i], pts[(i + 1) % n]);
            ((a.1 <= c && c < b.1) || (b.1 <= c && c < a.1))
                .then(|| a.0 + (b.0 - a.0) * (c - a.1) / (b.1 - a.1))
        })
        .collect();
    xs.sort_by(f64::total_cmp);
    xs.chunks_exact(2)
        .filter(|p| p[1] - p[0] > 1e-6)
        .map(|p| (p[0], p[1]))
        .collect()
}

/// Flying order: from the first piece of the first lane, always the unflown piece
/// with the nearest end, flown from that end. Returns (offset, from, to) along.
pub(super) fn order(segments: &[Segment]) -> Vec<Segment> {
    let mut left: Vec<Segment> = segments.to_vec();
    let mut out = Vec::with_capacity(left.len());
    if left.is_empty() {
        return out;
    }
    let first = left.remove(0);
    out.push(first);
    let mut here = Vector2::new(first.2, first.0);
    while !left.is_empty() {
        let mut best = (f64::INFINITY, 0, false);
        for (i, s) in left.iter().enumerate() {
            let da = (Vector2::new(s.1, s.0) - here).norm();
            let db = (Vector2::new(s.2, s.0) - here).norm();
            if da < best.0 {
                best = (da, i, false);
            }
            if db < best.0 {
                best = (db, i, true);
            }
        }
        let s = left.remove(best.1);
        let flown = if best.2 { (s.0, s.2, s.1) } else { s };
        here = Vector2::new(flown.2, flown.0);
        out.push(flown);
    }
    out
}
