//! SSIM over a loss region only: the weighted SSIM of pixels with weight zero adds nothing, and
//! its gradient reaches only the pixels within a window's radius of a weighted one, so a region
//! loss needs the SSIM only around its 16×16 tiles. The tiles holding a weighted pixel are cut
//! into pieces (per strip of `STRIP_TILES` tile rows, runs of such tiles across, gaps of up to
//! `GAP_TILES` bridged); each piece's SSIM is computed on its tiles (the core, the only pixels
//! it weights) plus the window's radius around them, where every weighted pixel's window and
//! every pixel its gradient reaches lie inside. The cores partition the weighted pixels, so the
//! pieces' sums add up to the whole image's, and their gradients (added where the margins
//! overlap) to its gradient: the same terms, summed in another order.

use rayon::prelude::*;

use super::{RADIUS, SsimWorkspace, ssim_in_bands};
use crate::raster::TILE_SIZE;

const TS: usize = TILE_SIZE as usize;
/// Tile rows per strip: taller strips add fewer margin rows, shorter ones follow a slanted
/// crack's hull more closely.
const STRIP_TILES: usize = 2;
/// Inactive tiles a run bridges: a gap this narrow costs less than the two margins it saves.
const GAP_TILES: usize = 1;

/// One piece: `[x0, y0, x1, y1)` in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Piece {
    /// The pixels whose SSIM it adds (tiles, clipped to the image).
    core: [usize; 4],
    /// The pixels it reads: the core and the window's radius around it, clipped to the image.
    input: [usize; 4],
}

impl Piece {
    fn input_size(&self) -> (usize, usize) {
        let [x0, y0, x1, y1] = self.input;
        (x1 - x0, y1 - y0)
    }
}

/// One piece's copies of its inputs, its gradient and its sum.
#[derive(Default)]
struct PieceScratch {
    ws: SsimWorkspace,
    x: Vec<f32>,
    y: Vec<f32>,
    weights: Vec<f32>,
    v: Vec<f32>,
    sum: f64,
}

/// Reusable state of [`RegionSsim::ssim_with_grad`]: after a few frames, no allocation.
#[derive(Default)]
pub struct RegionSsim {
    pieces: Vec<Piece>,
    scratch: Vec<PieceScratch>,
    active: Vec<bool>,
    columns: Vec<bool>,
}

/// Copies rows `y0..y1`, columns `x0..x1` of a `width`-wide image of `per` values a pixel.
fn copy_window(
    src: &[f32],
    width: usize,
    per: usize,
    [x0, y0, x1, y1]: [usize; 4],
    out: &mut Vec<f32>,
) {
    out.clear();
    for y in y0..y1 {
        out.extend_from_slice(&src[(y * width + x0) * per..(y * width + x1) * per]);
    }
}

impl RegionSsim {
    pub fn new() -> RegionSsim {
        RegionSsim::default()
    }

    /// Cuts the tiles holding a weighted pixel into pieces; returns the pixels they read.
    fn plan(&mut self, weights: &[f32], w: usize, h: usize) -> usize {
        let (tiles_x, tiles_y) = (w.div_ceil(TS), h.div_ceil(TS));
        self.active.clear();
        self.active.resize(tiles_x * tiles_y, false);
        for (y, row) in weights.chunks_exact(w).enumerate() {
            let base = (y / TS) * tiles_x;
            for (x, &a) in row.iter().enumerate() {
                if a != 0.0 {
                    self.active[base + x / TS] = true;
                }
            }
        }
        self.pieces.clear();
        let mut read = 0;
        for strip in (0..tiles_y).step_by(STRIP_TILES) {
            let rows = strip..tiles_y.min(strip + STRIP_TILES);
            self.columns.clear();
            self.columns.extend(
                (0..tiles_x).map(|tx| rows.clone().any(|ty| self.active[ty * tiles_x + tx])),
            );
            let mut tx = 0;
            while tx < tiles_x {
                if !self.columns[tx] {
                    tx += 1;
                    continue;
                }
                // A run: from this column to the last active one no more than GAP_TILES
                // inactive columns apart.
                let first = tx;
                let mut last = tx;
                while tx < tiles_x && tx <= last + GAP_TILES {
                    if self.columns[tx] {
                        last = tx;
                    }
                    tx += 1;
                }
                let active_row = |ty: usize| (first..=last).any(|c| self.active[ty * tiles_x + c]);
                let top = rows
                    .clone()
                    .find(|&ty| active_row(ty))
                    .unwrap_or(rows.start);
                let bottom = rows.clone().rev().find(|&ty| active_row(ty)).unwrap_or(top);
                let core = [
                    first * TS,
                    top * TS,
                    ((last + 1) * TS).min(w),
                    ((bottom + 1) * TS).min(h),
                ];
                let input = [
                    core[0].saturating_sub(RADIUS),
                    core[1].saturating_sub(RADIUS),
                    (core[2] + RADIUS).min(w),
                    (core[3] + RADIUS).min(h),
                ];
                let piece = Piece { core, input };
                let (iw, ih) = piece.input_size();
                read += iw * ih;
                self.pieces.push(piece);
            }
        }
        read
    }

    /// The pixels the pieces of `weights` read (the SSIM's pixel count on this path).
    pub fn pixels_read(&mut self, weights: &[f32], width: u32, height: u32) -> usize {
        self.plan(weights, width as usize, height as usize)
    }

    /// `ssim_with_grad(x, y, width, height, Some(weights), Some(v_x))` computed on the pieces
    /// around the weighted pixels only (`v_x` overwritten, zero beyond the pieces), or None,
    /// touching nothing, when the pieces would read as many pixels as the whole image.
    #[allow(clippy::too_many_arguments)]
    pub fn ssim_with_grad(
        &mut self,
        x: &[f32],
        y: &[f32],
        width: u32,
        height: u32,
        weights: &[f32],
        v_x: &mut [f32],
    ) -> Option<f64> {
        let (w, h) = (width as usize, height as usize);
        assert_eq!(weights.len(), w * h, "region ssim: weight count");
        assert_eq!(x.len(), w * h * 3, "region ssim: rendered image size");
        assert_eq!(y.len(), w * h * 3, "region ssim: target image size");
        assert_eq!(v_x.len(), w * h * 3, "region ssim: gradient size");
        if w == 0 || self.plan(weights, w, h) >= w * h {
            return None;
        }
        if self.scratch.len() < self.pieces.len() {
            self.scratch
                .resize_with(self.pieces.len(), PieceScratch::default);
        }
        self.pieces
            .par_iter()
            .zip(self.scratch.par_iter_mut())
            .for_each(|(piece, s)| {
                let (iw, ih) = piece.input_size();
                copy_window(x, w, 3, piece.input, &mut s.x);
                copy_window(y, w, 3, piece.input, &mut s.y);
                let [cx0, cy0, cx1, cy1] = piece.core;
                let [ix0, iy0, ..] = piece.input;
                s.weights.clear();
                for py in iy0..iy0 + ih {
                    for px in ix0..ix0 + iw {
                        let core = (cx0..cx1).contains(&px) && (cy0..cy1).contains(&py);
                        s.weights
                            .push(if core { weights[py * w + px] } else { 0.0 });
                    }
                }
                s.v.clear();
                s.v.resize(iw * ih * 3, 0.0);
                // One band: the pieces run in parallel instead.
                s.sum = ssim_in_bands(
                    &mut s.ws,
                    &s.x,
                    &s.y,
                    iw as u32,
                    ih as u32,
                    Some(&s.weights),
                    Some(&mut s.v),
                    ih,
                );
            });
        // In piece order: the same result for any thread count.
        v_x.fill(0.0);
        let mut total = 0.0f64;
        for (piece, s) in self.pieces.iter().zip(&self.scratch) {
            total += s.sum;
            let (iw, _) = piece.input_size();
            let [x0, y0, _, y1] = piece.input;
            for (row, yy) in s.v.chunks_exact(iw * 3).zip(y0..y1) {
                let at = (yy * w + x0) * 3;
                for (out, v) in v_x[at..at + iw * 3].iter_mut().zip(row) {
                    *out += v;
                }
            }
        }
        Some(total)
    }
}

#[cfg(test)]
mod tests {
    use super::super::ssim_with_grad;
    use super::*;

    fn image(n: usize, seed: u64) -> Vec<f32> {
        let mut rng = fastrand::Rng::with_seed(seed);
        (0..n).map(|_| rng.f32()).collect()
    }

    /// A thin slanted band, a disc touching the right edge, a lone pixel: hull-like weights
    /// normalised as the photometric loss normalises them.
    fn weights(w: usize, h: usize) -> Vec<f32> {
        let mut m = vec![0.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let (xi, yi) = (x as i64, y as i64);
                let band = (xi - 2 * yi / 3 - 20).abs() <= 2;
                let disc = (xi - w as i64 + 4).pow(2) + (yi - 60).pow(2) <= 14 * 14;
                if band || disc || (x, y) == (70, 5) {
                    m[y * w + x] = 1.0;
                }
            }
        }
        let mass: f32 = m.iter().sum();
        m.iter().map(|v| v / (3.0 * mass)).collect()
    }

    #[test]
    fn pieces_give_the_whole_images_ssim_and_gradient() {
        let (w, h) = (150usize, 97usize);
        let (x, y, a) = (image(w * h * 3, 1), image(w * h * 3, 2), weights(w, h));
        let mut whole_v = vec![0.0f32; w * h * 3];
        let whole = ssim_with_grad(
            &mut SsimWorkspace::new(),
            &x,
            &y,
            w as u32,
            h as u32,
            Some(&a),
            Some(&mut whole_v),
        );
        let mut region = RegionSsim::new();
        let read = region.pixels_read(&a, w as u32, h as u32);
        assert!(
            read < w * h * 3 / 4,
            "the pieces read {read} of {} pixels",
            w * h
        );
        let mut v = vec![f32::NAN; w * h * 3];
        let got = region
            .ssim_with_grad(&x, &y, w as u32, h as u32, &a, &mut v)
            .expect("sparse enough for pieces");
        assert!(
            (got - whole).abs() <= 1e-9 * whole.abs(),
            "{got} against {whole}"
        );
        let scale = whole_v.iter().fold(0.0f32, |m, g| m.max(g.abs()));
        let worst = v
            .iter()
            .zip(&whole_v)
            .fold(0.0f32, |m, (p, q)| m.max((p - q).abs()));
        assert!(
            scale > 0.0 && worst <= 1e-5 * scale,
            "gradient off by {worst} of {scale}"
        );
        // A second call (reused pieces and workspaces) gives the same bits.
        let mut again = vec![0.0f32; w * h * 3];
        let second = region.ssim_with_grad(&x, &y, w as u32, h as u32, &a, &mut again);
        assert_eq!(second.map(f64::to_bits), Some(got.to_bits()));
        assert!(
            again
                .iter()
                .zip(&v)
                .all(|(p, q)| p.to_bits() == q.to_bits())
        );
    }

    #[test]
    fn a_dense_region_is_left_to_the_whole_image() {
        let (w, h) = (40usize, 30usize);
        let a = vec![1.0 / (3.0 * (w * h) as f32); w * h];
        let (x, y) = (image(w * h * 3, 3), image(w * h * 3, 4));
        let mut v = vec![7.0f32; w * h * 3];
        let got = RegionSsim::new().ssim_with_grad(&x, &y, w as u32, h as u32, &a, &mut v);
        assert_eq!(got, None);
        assert!(v.iter().all(|&g| g == 7.0), "untouched");
    }
}
