//! Which row segments (8 pixels of one tile row) each intersection can touch, and the store the
//! forward fills for the backward: per intersection the segments it blended into, per tile the
//! `exp(-power)` of their lanes. It also copies each intersection's projected Gaussian and label
//! probabilities in tile and depth order, which both blends stream through. It must not blend.

use rayon::prelude::*;

use super::bin::TileBins;
use super::forward::{LANES, Splat2d};
use super::{Projected, TILE_SIZE};
use crate::simd::{Arith, simd_dispatch};

const TS: usize = TILE_SIZE as usize;

/// One tile's share of the store, as the forward uses it.
pub(crate) struct TileParts<'a> {
    pub masks: &'a mut [u32],
    pub vis: &'a mut [f32],
    pub splats: &'a [Splat2d],
    pub labels: &'a [f32],
}

/// What the forward leaves for the backward, sized once per frame by [`SegmentStore::prepare`].
#[derive(Debug, Default)]
pub(crate) struct SegmentStore {
    /// Per intersection: before the forward, the segments it can touch; after it, the ones it
    /// blended into or stopped a pixel in (the only ones the backward replays).
    pub masks: Vec<u32>,
    /// Per intersection its projected Gaussian, copied in tile and depth order: the blend loops
    /// then stream through it instead of missing the cache on every Gaussian of a tile.
    pub splats: Vec<Splat2d>,
    /// Per intersection its label probabilities (`label_channels` each), in the same order.
    pub labels: Vec<f32>,
    label_channels: usize,
    /// Per tile its first float in `vis` (`tiles + 1` entries): room for 8 lanes of every
    /// segment the tile's intersections can touch.
    offsets: Vec<usize>,
    /// `exp(-power)` per lane of the blended segments, -1 where the lane failed the skip test,
    /// per tile in replay order (intersection, then segment bit).
    vis: Vec<f32>,
    counts: Vec<usize>,
    /// [`power_limit`] per Gaussian: once per Gaussian rather than once per intersection.
    power_max: Vec<f32>,
}

impl SegmentStore {
    /// Computes every intersection's segment mask and reserves exact room for the stored
    /// falloffs (a per-tile growing buffer kept the worst case of every view, twice over).
    pub fn prepare(
        &mut self,
        projected: &Projected,
        bins: &TileBins,
        label_channels: usize,
        alpha_threshold: f32,
    ) {
        let tiles = bins.tile_count();
        self.power_max.clear();
        self.power_max.resize(projected.opacities.len(), 0.0);
        self.power_max
            .par_iter_mut()
            .zip(projected.opacities.par_iter())
            .for_each(|(p, &opacity)| *p = power_limit(opacity, alpha_threshold));
        let power_max = &self.power_max;
        // Not cleared: the tile loop below writes every entry, and zeroing first cost a pass
        // over a few megabytes per frame.
        resize_for_overwrite(&mut self.masks, bins.gaussian_ids.len());
        resize_for_overwrite(&mut self.splats, bins.gaussian_ids.len());
        self.counts.clear();
        self.counts.resize(tiles, 0);
        bins.split_by_tile(&mut self.masks, 1)
            .into_par_iter()
            .zip(bins.split_by_tile(&mut self.splats, 1))
            .zip(self.counts.par_iter_mut())
            .enumerate()
            .for_each(|(tile, ((masks, splats), count))| {
                *count = tile_masks(tile, masks, splats, projected, bins, power_max) * LANES;
            });
        let l = label_channels;
        self.label_channels = l;
        self.labels.clear();
        self.labels.resize(bins.gaussian_ids.len() * l, 0.0);
        if l > 0 {
            self.labels
                .par_chunks_mut(l)
                .zip(bins.gaussian_ids.par_iter())
                .for_each(|(dst, &g)| {
                    let g = g as usize;
                    dst.copy_from_slice(&projected.labels[g * l..(g + 1) * l]);
                });
        }
        self.offsets.clear();
        let mut total = 0;
        self.offsets.push(0);
        for &c in &self.counts {
            total += c;
            self.offsets.push(total);
        }
        // Never shrunk, never cleared: every float the backward reads was written by this
        // frame's forward first.
        if self.vis.len() < total {
            self.vis.resize(total, 0.0);
        }
    }

    /// Per tile its masks and its room for falloffs, disjoint, for the forward to fill, and its
    /// intersections' Gaussians and label probabilities.
    pub fn tiles_mut(&mut self, bins: &TileBins) -> Vec<TileParts<'_>> {
        let l = self.label_channels;
        let masks = bins.split_by_tile(&mut self.masks, 1);
        let mut rest = &mut self.vis[..];
        let mut parts = Vec::with_capacity(masks.len());
        for ((m, w), [start, end]) in masks
            .into_iter()
            .zip(self.offsets.windows(2))
            .zip(&bins.tile_ranges)
        {
            let (head, tail) = rest.split_at_mut(w[1] - w[0]);
            let (start, end) = (*start as usize, *end as usize);
            parts.push(TileParts {
                masks: m,
                vis: head,
                splats: &self.splats[start..end],
                labels: &self.labels[start * l..end * l],
            });
            rest = tail;
        }
        parts
    }

    /// A tile's falloffs as the forward wrote them.
    pub fn tile_vis(&self, tile: usize) -> &[f32] {
        &self.vis[self.offsets[tile]..self.offsets[tile + 1]]
    }
}

/// Sets `v`'s length to `len` for a caller that overwrites every entry: old values stay (only
/// new room is filled with defaults), so nothing is written twice.
pub(crate) fn resize_for_overwrite<T: Copy + Default>(v: &mut Vec<T>, len: usize) {
    if v.len() < len {
        v.resize(len, T::default());
    } else {
        v.truncate(len);
    }
}

/// Writes the segment mask and the projected Gaussian of each intersection of `tile`; returns
/// their total segment count.
#[inline(always)]
fn tile_masks_impl<F: Arith>(
    tile: usize,
    masks: &mut [u32],
    splats: &mut [Splat2d],
    projected: &Projected,
    bins: &TileBins,
    power_max: &[f32],
) -> usize {
    let tiles_x = bins.tiles_x as usize;
    let (ox, oy) = (
        ((tile % tiles_x) * TS) as f32,
        ((tile / tiles_x) * TS) as f32,
    );
    let inside = bins.tile_extent(tile);
    let [start, end] = bins.tile_ranges[tile];
    let ids = &bins.gaussian_ids[start as usize..end as usize];
    let mut segments = 0;
    for ((mask, splat), &g) in masks.iter_mut().zip(splats.iter_mut()).zip(ids) {
        let g = g as usize;
        let sp = Splat2d::load(projected, g);
        *mask = segment_mask::<F>(
            &sp,
            power_max[g],
            footprint::<F>(projected, g, ox, oy, inside),
            ox,
            oy,
        );
        *splat = sp;
        segments += mask.count_ones() as usize;
    }
    segments
}

simd_dispatch!(
    /// [`tile_masks_impl`] with AVX2 (or AVX-512VL) where the CPU has it: the 16-row mask
    /// vectorises and rounds with one instruction per bound ([`Arith`]'s floor and
    /// ceil; the baseline x86-64 build computes them with adds and compares, since its libm
    /// calls would keep the loop scalar).
    tile_masks => tile_masks_impl::<Arith>(
        tile: usize,
        masks: &mut [u32],
        splats: &mut [Splat2d],
        projected: &Projected,
        bins: &TileBins,
        power_max: &[f32],
    ) -> usize
);

/// The pixel columns `[x0, x1)` and rows `[y0, y1)` of a tile whose centres lie in a Gaussian's
/// extent box and in the image (`ox, oy` is the tile's top-left pixel, `inside` its columns and
/// rows within the image, [`TileBins::tile_extent`]), as whole numbers in floats: the mask
/// compares them with float rows and columns, and a round trip through `usize` cost a saturating
/// conversion each. The edge tiles' pixels past the image are never blended: the forward starts
/// them finished.
#[inline(always)]
pub(crate) fn footprint<F: Arith>(
    p: &Projected,
    g: usize,
    ox: f32,
    oy: f32,
    (columns, rows): (usize, usize),
) -> [f32; 4] {
    let m = p.means2d[g];
    let e = p.extents[g];
    let lo = |v: f32, n: usize| F::ceil(v).max(0.0).min(n as f32);
    let hi = |v: f32, n: usize| (F::floor(v) + 1.0).max(0.0).min(n as f32);
    [
        lo(m.x - e.x - 0.5 - ox, columns),
        lo(m.y - e.y - 0.5 - oy, rows),
        hi(m.x + e.x - 0.5 - ox, columns),
        hi(m.y + e.y - 0.5 - oy, rows),
    ]
}

/// Row segments of a tile (row `y`, half `h`: pixels `8h..8h + 8`) whose pixel centres can
/// reach the alpha threshold, as bit `2y + h`: per row the chord of the ellipse
/// `power <= ln(opacity / threshold)`, padded, clipped to the footprint `[x0, y0, x1, y1]`.
/// Pixels outside it would be skipped by the blend loop anyway, so visiting only these changes
/// no result; it saves the work on the ellipse's rounded ends. All 16 rows at once so the
/// square roots vectorise instead of running one dependent chain per row. The 0.05 px padding
/// dwarfs the rounding of the chord (a reciprocal instead of two divisions included).
#[inline(always)]
pub(crate) fn segment_mask<F: Arith>(
    sp: &Splat2d,
    power_max: f32,
    [x0, y0, x1, y1]: [f32; 4],
    ox: f32,
    oy: f32,
) -> u32 {
    if x0 >= x1 || y0 >= y1 {
        return 0;
    }
    let ts = TS as f32;
    let mut lo = [x0; TS];
    let mut hi = [x1; TS];
    if power_max.is_finite() {
        let inv_a = 1.0 / sp.a;
        let two_power = 2.0 * power_max;
        // Pixel centre ox + x + 0.5 = mean.x - dx, padded by 0.05 px either side.
        let (left_of_mean, right_of_mean) = (sp.mx - 0.5 - ox - 0.05, sp.mx - 0.5 - ox + 0.05);
        for y in 0..TS {
            let dy = sp.my - (oy + y as f32 + 0.5);
            // 0.5 (a dx² + c dy²) + b dx dy <= P  <=>  a dx² + 2 b dy dx + c dy² - 2 P <= 0.
            let disc = sp.b * sp.b * dy * dy - sp.a * (sp.c * dy * dy - two_power);
            let root = disc.max(0.0).sqrt();
            let b_dy = sp.b * dy;
            // The roots are dx = (-b dy ± root) / a; the columns are mean.x - dx.
            let l = F::ceil(left_of_mean + (b_dy - root) * inv_a)
                .max(0.0)
                .min(ts);
            let h = (F::floor(right_of_mean + (b_dy + root) * inv_a) + 1.0)
                .max(0.0)
                .min(ts);
            // `!(disc >= 0)` also empties the row when disc is NaN.
            let empty = !(disc >= 0.0);
            lo[y] = if empty { ts } else { l.max(x0) };
            hi[y] = if empty { 0.0 } else { h.min(x1) };
        }
    }
    let lanes = LANES as f32;
    let mut bits = [0u32; TS];
    for y in 0..TS {
        let row = y as f32;
        let rows = row >= y0 && row < y1 && lo[y] < hi[y];
        let left = rows && lo[y] < lanes;
        let right = rows && hi[y] > lanes;
        bits[y] = ((left as u32) | ((right as u32) << 1)) << (2 * y);
    }
    bits.iter().fold(0, |m, &b| m | b)
}

/// `ln(opacity / threshold)` with a safety margin: the largest power that can still blend;
/// infinite when there is no threshold.
#[inline(always)]
pub(crate) fn power_limit(opacity: f32, alpha_threshold: f32) -> f32 {
    if alpha_threshold > 0.0 {
        (opacity / alpha_threshold).ln() * 1.001 + 0.01
    } else {
        f32::INFINITY
    }
}
