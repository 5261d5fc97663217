//! Planar Y′CbCr (a Y4M frame) → the camera's output formats, written straight into
//! the caller's (the loaned frame's) slice. Pure functions, no I/O.
//!
//! The colour model is BT.601 with the constants [`crate::render::rgb_to_ycbcr`] uses
//! (`Kr = 0.299`, `Kb = 0.114`), inverted:
//! `R = Y + 1.402·Cr′`, `G = Y − 0.344136·Cb′ − 0.714136·Cr′`, `B = Y + 1.772·Cb′`
//! with `Cb′ = Cb − 128`, `Cr′ = Cr − 128`. A **limited** ("TV", 16–235 / 16–240)
//! input is first expanded to full range: `Y = (Y − 16)·255/219`,
//! `C = (C − 128)·255/224 + 128`. Every output is full range, like the synthetic
//! source's NV12, so subscribers see one convention whatever the source.
//!
//! 4:2:0 chroma is used as is: one Cb/Cr pair for each 2×2 block (the last column or
//! row of an odd size has its own); chroma siting (`420jpeg`/`420mpeg2`/`420paldv`)
//! is not resampled. Mono input has neutral chroma (grey).

use crate::y4m::{Chroma, Y4mHeader};

const KR: f64 = 0.299;
const KB: f64 = 0.114;
const KG: f64 = 1.0 - KR - KB;
/// Fixed-point fraction bits of the conversion tables.
const SHIFT: u32 = 16;

/// The value range of the input's samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Range {
    /// 0–255 (JPEG/JFIF).
    Full,
    /// Y 16–235, Cb/Cr 16–240 (studio/TV).
    Limited,
}

/// Lookup tables of one input range.
#[derive(Debug, Clone)]
pub struct Converter {
    /// Input luma → full-range luma.
    y: [u8; 256],
    /// Input chroma → full-range chroma.
    c: [u8; 256],
    /// Input chroma → its contribution to R, G, B (fixed point, `SHIFT` bits).
    r_cr: [i32; 256],
    g_cb: [i32; 256],
    g_cr: [i32; 256],
    b_cb: [i32; 256],
}

impl Converter {
    pub fn new(range: Range) -> Self {
        let mut k = Converter {
            y: [0; 256],
            c: [0; 256],
            r_cr: [0; 256],
            g_cb: [0; 256],
            g_cr: [0; 256],
            b_cb: [0; 256],
        };
        let scale = f64::from(1u32 << SHIFT);
        for i in 0..256usize {
            let v = i as f64;
            let (y, c) = match range {
                Range::Full => (v, v),
                Range::Limited => (
                    (v - 16.0) * 255.0 / 219.0,
                    (v - 128.0) * 255.0 / 224.0 + 128.0,
                ),
            };
            k.y[i] = y.round().clamp(0.0, 255.0) as u8;
            k.c[i] = c.round().clamp(0.0, 255.0) as u8;
            // From the full-range chroma (unrounded, for accuracy).
            let c = c - 128.0;
            k.r_cr[i] = (2.0 * (1.0 - KR) * c * scale).round() as i32;
            k.b_cb[i] = (2.0 * (1.0 - KB) * c * scale).round() as i32;
            k.g_cb[i] = (2.0 * KB * (1.0 - KB) / KG * c * scale).round() as i32;
            k.g_cr[i] = (2.0 * KR * (1.0 - KR) / KG * c * scale).round() as i32;
        }
        k
    }

    /// One pixel: input Y, Cb, Cr → full-range RGB.
    #[inline]
    pub fn rgb(&self, y: u8, cb: u8, cr: u8) -> [u8; 3] {
        let y = (i32::from(self.y[usize::from(y)]) << SHIFT) + (1 << (SHIFT - 1));
        let (cb, cr) = (usize::from(cb), usize::from(cr));
        let clamp = |v: i32| (v >> SHIFT).clamp(0, 255) as u8;
        [
            clamp(y + self.r_cr[cr]),
            clamp(y - self.g_cb[cb] - self.g_cr[cr]),
            clamp(y + self.b_cb[cb]),
        ]
    }

    /// Converts one frame of `src` (the Y4M planes of `h`) into NV12 in `out`: luma
    /// rows then interleaved CbCr rows, both `stride` bytes apart. `h` must have an
    /// even width and height (NV12 has no odd sizes); returns false, writing nothing,
    /// if the sizes do not fit.
    pub fn to_nv12(&self, h: &Y4mHeader, src: &[u8], stride: usize, out: &mut [u8]) -> bool {
        let (w, ht) = (h.width as usize, h.height as usize);
        if w % 2 != 0 || ht % 2 != 0 || stride < w || src.len() != h.frame_len() {
            return false;
        }
        if out.len() < stride * ht + stride * (ht / 2) {
            return false;
        }
        let (luma, uv) = out.split_at_mut(stride * ht);
        for (row, src_row) in luma.chunks_mut(stride).zip(src.chunks(w)) {
            for (o, &s) in row.iter_mut().zip(src_row) {
                *o = self.y[usize::from(s)];
            }
        }
        let (cw, ch) = (w / 2, ht / 2);
        match h.chroma {
            Chroma::Mono => {
                for row in uv.chunks_mut(stride).take(ch) {
                    row[..w].fill(128);
                }
            }
            Chroma::C420 => {
                let (cb, cr) = src[w * ht..].split_at(cw * ch);
                for ((row, cb), cr) in uv.chunks_mut(stride).zip(cb.chunks(cw)).zip(cr.chunks(cw)) {
                    for ((pair, &b), &r) in row[..w].chunks_exact_mut(2).zip(cb).zip(cr) {
                        pair[0] = self.c[usize::from(b)];
                        pair[1] = self.c[usize::from(r)];
                    }
                }
            }
        }
        true
    }

    /// Converts one frame of `src` into RGB24 in `out`, rows `stride` bytes apart.
    /// Returns false, writing nothing, if the sizes do not fit.
    pub fn to_rgb24(&self, h: &Y4mHeader, src: &[u8], stride: usize, out: &mut [u8]) -> bool {
        let (w, ht) = (h.width as usize, h.height as usize);
        if stride < w * 3 || src.len() != h.frame_len() || out.len() < stride * ht {
            return false;
        }
        let (luma, chroma) = src.split_at(w * ht);
        let (cw, ch) = h.chroma_size();
        let (cb, cr) = chroma.split_at(cw * ch);
        for (j, (row, y_row)) in out.chunks_mut(stride).zip(luma.chunks(w)).enumerate() {
            let px = row[..w * 3].chunks_exact_mut(3).zip(y_row);
            match h.chroma {
                Chroma::Mono => {
                    for (o, &y) in px {
                        o.fill(self.y[usize::from(y)]);
                    }
                }
                Chroma::C420 => {
                    let c0 = (j / 2) * cw;
                    let (cb_row, cr_row) = (&cb[c0..c0 + cw], &cr[c0..c0 + cw]);
                    for (i, (o, &y)) in px.enumerate() {
                        o.copy_from_slice(&self.rgb(y, cb_row[i / 2], cr_row[i / 2]));
                    }
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::rgb_to_ycbcr;

    #[test]
    fn full_range_inverts_the_renderers_rgb_to_ycbcr() {
        let k = Converter::new(Range::Full);
        let mut worst = 0;
        for r in (0..=255u8).step_by(15) {
            for g in (0..=255u8).step_by(15) {
                for b in (0..=255u8).step_by(15) {
                    let [y, cb, cr] = rgb_to_ycbcr([r, g, b]);
                    let back = k.rgb(y, cb, cr);
                    for (a, o) in back.iter().zip([r, g, b]) {
                        worst = worst.max(a.abs_diff(o));
                    }
                }
            }
        }
        // Rounding of Y, Cb and Cr to bytes: at most two steps back.
        assert!(worst <= 2, "worst channel error {worst}");
        assert_eq!(k.rgb(255, 128, 128), [255, 255, 255]);
        assert_eq!(k.rgb(0, 128, 128), [0, 0, 0]);
    }

    #[test]
    fn limited_range_expands_to_full() {
        let k = Converter::new(Range::Limited);
        assert_eq!(k.rgb(16, 128, 128), [0, 0, 0]);
        assert_eq!(k.rgb(235, 128, 128), [255, 255, 255]);
        assert_eq!(k.rgb(0, 128, 128), [0, 0, 0]);
        // BT.601 limited red (81, 90, 240).
        let red = k.rgb(81, 90, 240);
        assert!(red[0] >= 253 && red[1] <= 2 && red[2] <= 2, "{red:?}");
    }

    fn header(w: u32, h: u32, chroma: Chroma) -> Y4mHeader {
        Y4mHeader {
            width: w,
            height: h,
            rate: None,
            chroma,
        }
    }

    #[test]
    fn nv12_interleaves_the_chroma_planes() {
        let h = header(4, 2, Chroma::C420);
        let src = [1, 2, 3, 4, 5, 6, 7, 8, 10, 11, 20, 21];
        let mut out = [0u8; 12];
        assert!(Converter::new(Range::Full).to_nv12(&h, &src, 4, &mut out));
        assert_eq!(out, [1, 2, 3, 4, 5, 6, 7, 8, 10, 20, 11, 21]);
        // Mono: neutral chroma.
        let h = header(4, 2, Chroma::Mono);
        assert!(Converter::new(Range::Full).to_nv12(&h, &src[..8], 4, &mut out));
        assert_eq!(out[8..], [128; 4]);
        // Odd sizes and short buffers are refused, not a panic.
        assert!(!Converter::new(Range::Full).to_nv12(
            &header(3, 2, Chroma::Mono),
            &[0; 6],
            3,
            &mut out
        ));
        assert!(!Converter::new(Range::Full).to_nv12(&h, &src[..8], 4, &mut out[..11]));
    }

    #[test]
    fn rgb24_of_an_odd_size_uses_the_last_chroma_column_and_row() {
        // 3×3: chroma 2×2. The right column and bottom row have their own chroma.
        let k = Converter::new(Range::Full);
        let h = header(3, 3, Chroma::C420);
        let [y, cb, cr] = rgb_to_ycbcr([200, 30, 30]);
        let mut src = vec![y; 9];
        src.extend_from_slice(&[128, 128, 128, cb]); // Cb
        src.extend_from_slice(&[128, 128, 128, cr]); // Cr
        let mut out = vec![0u8; 27];
        assert!(k.to_rgb24(&h, &src, 9, &mut out));
        let px = |x: usize, y: usize| &out[y * 9 + x * 3..y * 9 + x * 3 + 3];
        assert_eq!(px(0, 0), [y, y, y]);
        let red = px(2, 2);
        assert!(red[0] >= 198 && red[1] <= 32 && red[2] <= 32, "{red:?}");
        assert_eq!(px(1, 2), [y, y, y]);
        assert!(!k.to_rgb24(&h, &src[1..], 9, &mut out));
    }
}
