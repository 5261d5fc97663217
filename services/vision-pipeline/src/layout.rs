//! Output layouts (VIDEO_OUTPUT layout 0–6, detection overlay 0–5).
//!
//! The output frame is split into the detection overlay and the user views:
//!
//! - Overlay modes 2–5 take a strip *outside* the user views — a column on the right
//!   (2) or left (3), a row on the top (4) or bottom (5) — one tile side wide, and the
//!   views share what is left. Mode 1 is one picture-in-picture tile in the top right
//!   corner, drawn over the views; mode 0 has no overlay.
//! - **Tile side** (`single_detection_size`) = `min(width, height) / 5` for every
//!   mode (144 px at 1280×720, 216 at 1920×1080, 96 at 640×480). The number of tiles is
//!   the spec's `floor(limiting length / side)`: the output height for columns (5),
//!   the output width for rows (8 at 16:9). The overlay box is exactly the tiles
//!   (`n × side` long, from the top / left of the strip); the rest of the strip stays
//!   black.
//! - Views tile the view area exactly: splitting a length into parts gives the
//!   remainder pixels to the last part (no gaps, no overlap).
//!
//! Out-of-range modes (the caller checks them) are treated as 0, so nothing panics.

/// Where everything goes in the output frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Layout {
    /// User views (x, y, w, h), 1–4; layout 6 (debug) has one showing the source frame.
    pub views: Vec<[u16; 4]>,
    /// True for layout 6: the one view shows the whole source frame.
    pub debug_source: bool,
    /// The whole detection overlay (zero if mode 0).
    pub overlay_box: [u16; 4],
    /// Side of one square detection tile.
    pub tile_size: u16,
    /// Each tile's rectangle, in slot order.
    pub tiles: Vec<[u16; 4]>,
}

/// The tile side divides the output's shorter dimension by this.
pub const TILE_DIVISOR: u16 = 5;

/// Highest layout and overlay modes.
pub const MAX_LAYOUT: u8 = 6;
pub const MAX_OVERLAY: u8 = 5;

/// User views of a layout (1–4; the debug layout 6 shows one).
pub fn views_in_layout(layout: u8) -> u8 {
    match layout {
        1 | 2 => 2,
        3 => 3,
        4 | 5 => 4,
        _ => 1,
    }
}

/// Views and tiles for an output of `width`×`height` (layout 0–6, overlay 0–5; the
/// caller has checked the ranges).
pub fn compute(layout: u8, overlay: u8, width: u16, height: u16) -> Layout {
    let layout = if layout > MAX_LAYOUT { 0 } else { layout };
    let overlay = if overlay > MAX_OVERLAY { 0 } else { overlay };
    let side = width.min(height) / TILE_DIVISOR;
    // The view area after a strip, and the tiles.
    let (area, tiles) = if side == 0 || overlay == 0 {
        ([0, 0, width, height], Vec::new())
    } else {
        match overlay {
            1 => ([0, 0, width, height], vec![[width - side, 0, side, side]]),
            2 => (
                [0, 0, width - side, height],
                column(width - side, side, height),
            ),
            3 => ([side, 0, width - side, height], column(0, side, height)),
            4 => ([0, side, width, height - side], row(0, side, width)),
            _ => (
                [0, 0, width, height - side],
                row(height - side, side, width),
            ),
        }
    };
    let overlay_box = match (tiles.first(), tiles.last()) {
        (Some(first), Some(last)) => [
            first[0],
            first[1],
            last[0] + last[2] - first[0],
            last[1] + last[3] - first[1],
        ],
        _ => [0; 4],
    };
    Layout {
        views: views(layout, area),
        debug_source: layout == 6,
        overlay_box,
        tile_size: if tiles.is_empty() { 0 } else { side },
        tiles,
    }
}

/// `n` tiles down a column at `x`.
fn column(x: u16, side: u16, height: u16) -> Vec<[u16; 4]> {
    (0..height / side)
        .map(|i| [x, i * side, side, side])
        .collect()
}

/// `n` tiles along a row at `y`.
fn row(y: u16, side: u16, width: u16) -> Vec<[u16; 4]> {
    (0..width / side)
        .map(|i| [i * side, y, side, side])
        .collect()
}

/// `len` split into `n` parts (offset, length), the remainder to the last.
fn split(start: u16, len: u16, n: u16) -> Vec<(u16, u16)> {
    let part = len / n;
    (0..n)
        .map(|i| {
            let offset = start + i * part;
            let size = if i + 1 == n { len - i * part } else { part };
            (offset, size)
        })
        .collect()
}

/// The user views of `layout` in `area`.
fn views(layout: u8, [x, y, w, h]: [u16; 4]) -> Vec<[u16; 4]> {
    let grid = |top: u16, bottom: u16| -> Vec<[u16; 4]> {
        let rows = split(y, h, 2);
        let (top_row, bottom_row) = (rows[0], rows[1]);
        let mut out: Vec<[u16; 4]> = split(x, w, top)
            .into_iter()
            .map(|(cx, cw)| [cx, top_row.0, cw, top_row.1])
            .collect();
        out.extend(
            split(x, w, bottom)
                .into_iter()
                .map(|(cx, cw)| [cx, bottom_row.0, cw, bottom_row.1]),
        );
        out
    };
    match layout {
        1 => grid(1, 1),
        2 => split(x, w, 2)
            .into_iter()
            .map(|(cx, cw)| [cx, y, cw, h])
            .collect(),
        3 => grid(2, 1),
        4 => grid(2, 2),
        5 => grid(3, 1),
        _ => vec![[x, y, w, h]],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(r: &[u16; 4]) -> u64 {
        u64::from(r[2]) * u64::from(r[3])
    }

    fn overlaps(a: &[u16; 4], b: &[u16; 4]) -> bool {
        let (ax, ay, aw, ah) = (a[0], a[1], a[2], a[3]);
        let (bx, by, bw, bh) = (b[0], b[1], b[2], b[3]);
        ax < bx + bw && bx < ax + aw && ay < by + bh && by < ay + ah
    }

    fn inside(r: &[u16; 4], outer: [u16; 4]) -> bool {
        r[0] >= outer[0]
            && r[1] >= outer[1]
            && u32::from(r[0]) + u32::from(r[2]) <= u32::from(outer[0]) + u32::from(outer[2])
            && u32::from(r[1]) + u32::from(r[3]) <= u32::from(outer[1]) + u32::from(outer[3])
    }

    /// The views cover `area` exactly: inside, no overlap, areas add up.
    fn assert_tiles(views: &[[u16; 4]], area_rect: [u16; 4]) {
        for (i, a) in views.iter().enumerate() {
            assert!(inside(a, area_rect), "{a:?} outside {area_rect:?}");
            assert!(a[2] > 0 && a[3] > 0);
            for b in &views[i + 1..] {
                assert!(!overlaps(a, b), "{a:?} overlaps {b:?}");
            }
        }
        let total: u64 = views.iter().map(area).sum();
        assert_eq!(total, area(&area_rect));
    }

    #[test]
    fn every_layout_tiles_the_frame() {
        for (width, height) in [(1280, 720), (1920, 1080), (641, 481), (640, 480)] {
            for layout in 0..=6 {
                let l = compute(layout, 0, width, height);
                assert_eq!(l.views.len(), usize::from(views_in_layout(layout)));
                assert_tiles(&l.views, [0, 0, width, height]);
                assert_eq!(l.debug_source, layout == 6);
                assert!(l.tiles.is_empty() && l.overlay_box == [0; 4]);
            }
        }
    }

    #[test]
    fn layout_shapes() {
        let l = compute(1, 0, 1280, 720);
        assert_eq!(l.views, vec![[0, 0, 1280, 360], [0, 360, 1280, 360]]);
        let l = compute(2, 0, 1280, 720);
        assert_eq!(l.views, vec![[0, 0, 640, 720], [640, 0, 640, 720]]);
        let l = compute(3, 0, 1280, 720);
        assert_eq!(
            l.views,
            vec![[0, 0, 640, 360], [640, 0, 640, 360], [0, 360, 1280, 360]]
        );
        let l = compute(4, 0, 1280, 720);
        assert_eq!(l.views[3], [640, 360, 640, 360]);
        let l = compute(5, 0, 1280, 721);
        assert_eq!(
            l.views,
            vec![
                [0, 0, 426, 360],
                [426, 0, 426, 360],
                [852, 0, 428, 360],
                [0, 360, 1280, 361]
            ]
        );
    }

    #[test]
    fn overlay_strips_sit_outside_the_views() {
        let (w, h) = (1280u16, 720u16);
        let side = 144;
        for overlay in 2..=5 {
            for layout in 0..=6 {
                let l = compute(layout, overlay, w, h);
                assert_eq!(l.tile_size, side);
                let expected = if overlay <= 3 { h / side } else { w / side };
                assert_eq!(l.tiles.len(), usize::from(expected), "overlay {overlay}");
                let view_area = match overlay {
                    2 => [0, 0, w - side, h],
                    3 => [side, 0, w - side, h],
                    4 => [0, side, w, h - side],
                    _ => [0, 0, w, h - side],
                };
                assert_tiles(&l.views, view_area);
                for t in &l.tiles {
                    assert_eq!((t[2], t[3]), (side, side));
                    assert!(inside(t, l.overlay_box) && inside(t, [0, 0, w, h]));
                    assert!(l.views.iter().all(|v| !overlaps(v, t)));
                }
                assert_eq!(area(&l.overlay_box), l.tiles.iter().map(area).sum::<u64>());
            }
        }
        assert_eq!(compute(0, 2, w, h).overlay_box, [w - side, 0, side, 720]);
        assert_eq!(compute(0, 4, w, h).overlay_box, [0, 0, 1152, side]);
        assert_eq!(compute(0, 5, 1920, 1080).tiles.len(), 8);
        assert_eq!(compute(0, 5, 1920, 1080).tiles[0], [0, 864, 216, 216]);
    }

    #[test]
    fn picture_in_picture_covers_the_top_right() {
        let l = compute(4, 1, 1280, 720);
        assert_eq!(l.tiles, vec![[1136, 0, 144, 144]]);
        assert_eq!(l.overlay_box, [1136, 0, 144, 144]);
        assert_tiles(&l.views, [0, 0, 1280, 720]);
    }

    #[test]
    fn odd_inputs_do_not_panic() {
        for (w, h) in [(0, 0), (4, 4), (1, 1000), (65535, 65535), (7, 3)] {
            for layout in [0, 3, 5, 6, 7, 200] {
                for overlay in [0, 1, 2, 3, 4, 5, 6, 255] {
                    let l = compute(layout, overlay, w, h);
                    assert!(!l.views.is_empty());
                }
            }
        }
        assert_eq!(compute(9, 9, 1280, 720), compute(0, 0, 1280, 720));
    }
}
