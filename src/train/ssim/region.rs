//! SSIM over a loss region only: the weighted SSIM of pixels with weight zero adds nothing, and
//! its gradient reaches only the pixels within a window's radius of a weighted one, so a region
//! loss needs the SSIM only around its pixels. The 16×16 tiles holding a weighted pixel are cut
//! into pieces (per strip of `STRIP_TILES` tile rows, runs of such tiles across, gaps of up to
//! `GAP_TILES` bridged); each piece's SSIM is computed on its core, the bounding box of the
//! weighted pixels in its tiles (the only pixels it weights), plus the window's radius around
//! it, where every weighted pixel's window and every pixel its gradient reaches lie inside. The
//! cores partition the weighted pixels, so the pieces' sums add up to the whole image's, and
//! their gradients (added where the margins overlap) to its gradient: the same terms, summed in
//! another order. The region is blended into the render as the photometric loss does
//! (`m·x + (1-m)·t`) while each piece copies its pixels, so no whole-image blend is made.

use rayon::prelude::*;

use super::{RADIUS, SsimWorkspace, ssim_in_bands};
use crate::raster::TILE_SIZE;
use crate::train::region_runs::RegionRuns;

const TS: usize = TILE_SIZE as usize;
/// Tile rows per strip: taller strips add fewer margin rows, shorter ones follow a slanted
/// crack's hull more closely.
const STRIP_TILES: usize = 2;
/// Inactive tiles a run bridges: a gap this narrow costs less than the two margins it saves.
const GAP_TILES: usize = 1;

/// One piece: `[x0, y0, x1, y1)` in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Piece {
    /// The pixels whose SSIM it adds (the weighted pixels' bounding box in its tiles).
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

/// A pixel box `[x0, y0, x1, y1)`; empty while `x0 >= x1`.
type PixelBox = [usize; 4];
const EMPTY_BOX: PixelBox = [usize::MAX, usize::MAX, 0, 0];

fn is_empty(b: &PixelBox) -> bool {
    b[0] >= b[2]
}

fn union(a: &mut PixelBox, b: &PixelBox) {
    a[0] = a[0].min(b[0]);
    a[1] = a[1].min(b[1]);
    a[2] = a[2].max(b[2]);
    a[3] = a[3].max(b[3]);
}

/// Reusable state of [`RegionSsim::ssim_with_grad`]: after a few frames, no allocation.
#[derive(Default)]
pub struct RegionSsim {
    pieces: Vec<Piece>,
    scratch: Vec<PieceScratch>,
    /// Per tile, the bounding box of its weighted pixels.
    tile_boxes: Vec<PixelBox>,
    columns: Vec<bool>,
    runs: RegionRuns,
}

/// The region's inputs: the render, the photo, the region's per-pixel weights `m` (in [0, 1])
/// and the scale that turns them into the SSIM's pixel weights (`a = m·scale`).
#[derive(Clone, Copy)]
pub struct RegionImages<'a> {
    pub rendered: &'a [f32],
    pub target: &'a [f32],
    pub region: &'a [f32],
    pub scale: f32,
}

impl RegionSsim {
    pub fn new() -> RegionSsim {
        RegionSsim::default()
    }

    /// Cuts the tiles holding a weighted pixel of `runs` into pieces; returns the pixels they
    /// read.
    fn plan(&mut self, runs: &RegionRuns) -> usize {
        let (w, h) = (runs.width(), runs.height());
        let (tiles_x, tiles_y) = (w.div_ceil(TS), h.div_ceil(TS));
        self.tile_boxes.clear();
        self.tile_boxes.resize(tiles_x * tiles_y, EMPTY_BOX);
        for (y, [x0, x1]) in runs.iter() {
            let base = (y / TS) * tiles_x;
            for tx in x0 / TS..=(x1 - 1) / TS {
                let span = [x0.max(tx * TS), y, x1.min((tx + 1) * TS), y + 1];
                union(&mut self.tile_boxes[base + tx], &span);
            }
        }
        self.pieces.clear();
        let mut read = 0;
        for strip in (0..tiles_y).step_by(STRIP_TILES) {
            let rows = strip..tiles_y.min(strip + STRIP_TILES);
            self.columns.clear();
            self.columns.extend((0..tiles_x).map(|tx| {
                rows.clone()
                    .any(|ty| !is_empty(&self.tile_boxes[ty * tiles_x + tx]))
            }));
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
                let mut core = EMPTY_BOX;
                for ty in rows.clone() {
                    for b in &self.tile_boxes[ty * tiles_x + first..=ty * tiles_x + last] {
                        if !is_empty(b) {
                            union(&mut core, b);
                        }
                    }
                }
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
        let mut runs = std::mem::take(&mut self.runs);
        runs.rebuild(weights, width as usize, height as usize);
        let read = self.plan(&runs);
        self.runs = runs;
        read
    }

    /// `ssim_with_grad(m·x + (1-m)·t, t, width, height, Some(m·scale), Some(v_x))` computed on
    /// the pieces around the region's pixels (`runs`, those of `images.region`) only (`v_x`
    /// overwritten, zero beyond the pieces), or None, touching nothing, when the pieces would
    /// read as many pixels as the whole image.
    pub fn ssim_with_grad(
        &mut self,
        images: RegionImages<'_>,
        runs: &RegionRuns,
        v_x: &mut [f32],
    ) -> Option<f64> {
        let (w, h) = (runs.width(), runs.height());
        let RegionImages {
            rendered,
            target,
            region,
            scale,
        } = images;
        assert_eq!(region.len(), w * h, "region ssim: weight count");
        assert_eq!(
            rendered.len(),
            w * h * 3,
            "region ssim: rendered image size"
        );
        assert_eq!(target.len(), w * h * 3, "region ssim: target image size");
        assert_eq!(v_x.len(), w * h * 3, "region ssim: gradient size");
        if w == 0 || self.plan(runs) >= w * h {
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
                let [cx0, cy0, cx1, cy1] = piece.core;
                let [ix0, iy0, ix1, iy1] = piece.input;
                s.x.clear();
                s.y.clear();
                s.weights.clear();
                for py in iy0..iy1 {
                    let row = py * w;
                    s.y.extend_from_slice(&target[(row + ix0) * 3..(row + ix1) * 3]);
                    for px in ix0..ix1 {
                        let p = row + px;
                        let m = region[p];
                        let (x, t) = (&rendered[p * 3..p * 3 + 3], &target[p * 3..p * 3 + 3]);
                        for c in 0..3 {
                            s.x.push(m * x[c] + (1.0 - m) * t[c]);
                        }
                        let core = (cx0..cx1).contains(&px) && (cy0..cy1).contains(&py);
                        s.weights.push(if core { m * scale } else { 0.0 });
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

    /// A thin slanted band, a disc touching the right edge, a lone pixel: a hull-like region.
    fn region(w: usize, h: usize) -> Vec<f32> {
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
        m
    }

    /// The pieces' SSIM of `m·x + (1-m)·y` against the whole image's.
    fn ssim_of_pieces(
        region: &mut RegionSsim,
        (x, y, m): (&[f32], &[f32], &[f32]),
        w: usize,
        h: usize,
        v: &mut [f32],
    ) -> Option<f64> {
        let mass: f32 = m.iter().sum();
        let images = RegionImages {
            rendered: x,
            target: y,
            region: m,
            scale: 1.0 / (3.0 * mass),
        };
        region.ssim_with_grad(images, &RegionRuns::of(m, w, h), v)
    }

    #[test]
    fn pieces_give_the_whole_images_ssim_and_gradient() {
        let (w, h) = (150usize, 97usize);
        let (x, y, m) = (image(w * h * 3, 1), image(w * h * 3, 2), region(w, h));
        let mass: f32 = m.iter().sum();
        let a: Vec<f32> = m.iter().map(|v| v * (1.0 / (3.0 * mass))).collect();
        let blended: Vec<f32> = (0..w * h * 3)
            .map(|i| m[i / 3] * x[i] + (1.0 - m[i / 3]) * y[i])
            .collect();
        let mut whole_v = vec![0.0f32; w * h * 3];
        let whole = ssim_with_grad(
            &mut SsimWorkspace::new(),
            &blended,
            &y,
            w as u32,
            h as u32,
            Some(&a),
            Some(&mut whole_v),
        );
        let mut pieces = RegionSsim::new();
        let read = pieces.pixels_read(&m, w as u32, h as u32);
        assert!(
            read < w * h * 3 / 4,
            "the pieces read {read} of {} pixels",
            w * h
        );
        let mut v = vec![f32::NAN; w * h * 3];
        let got = ssim_of_pieces(&mut pieces, (&x, &y, &m), w, h, &mut v)
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
        let second = ssim_of_pieces(&mut pieces, (&x, &y, &m), w, h, &mut again);
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
        let m = vec![1.0; w * h];
        let (x, y) = (image(w * h * 3, 3), image(w * h * 3, 4));
        let mut v = vec![7.0f32; w * h * 3];
        let got = ssim_of_pieces(&mut RegionSsim::new(), (&x, &y, &m), w, h, &mut v);
        assert_eq!(got, None);
        assert!(v.iter().all(|&g| g == 7.0), "untouched");
    }

    #[test]
    fn a_piece_reads_its_pixels_and_the_window_around_them_only() {
        // One pixel inside a tile reads its 11×11 window, not its tile's 26×26; a row of a tile
        // reads 11 rows of the tile's width and both margins.
        let (w, h) = (96usize, 64usize);
        let mut m = vec![0.0f32; w * h];
        m[20 * w + 40] = 1.0;
        assert_eq!(
            RegionSsim::new().pixels_read(&m, w as u32, h as u32),
            11 * 11
        );
        m[20 * w + 40] = 0.0;
        m[40 * w + 16..40 * w + 32].fill(1.0);
        assert_eq!(
            RegionSsim::new().pixels_read(&m, w as u32, h as u32),
            (16 + 10) * 11
        );
    }
}
