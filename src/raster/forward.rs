//! Rasterize forward: per 16×16 tile, blend its depth-sorted Gaussians front to back with the
//! 3DGS thresholds, in gsplat's exact order of tests. Gaussian-major over 8-pixel row segments
//! so the pixel loop vectorises; it must not project or sort.

use glam::Vec3;
use rayon::prelude::*;

use super::bin::TileBins;
use super::fast_exp::{LOG2_E, exp2_parts};
use super::segments::SegmentStore;
use super::{Projected, RenderOutput, RenderSettings, TILE_PIXELS, TILE_SIZE, TRANSMITTANCE_MIN};
use crate::simd::{Arith, simd_dispatch};

/// Pixels evaluated together (one AVX register of f32).
pub(crate) const LANES: usize = 8;
const TS: usize = TILE_SIZE as usize;

/// Planar channels of the tile state: transmittance, RGB, depth, then the labels.
pub(crate) const CH_T: usize = 0;
pub(crate) const CH_RGB: usize = 1;
pub(crate) const CH_DEPTH: usize = 4;
pub(crate) const CH_LABELS: usize = 5;

pub(crate) fn state_channels(label_channels: usize) -> usize {
    CH_LABELS + label_channels
}

/// One projected Gaussian as the blending loops read it.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Splat2d {
    pub mx: f32,
    pub my: f32,
    pub a: f32,
    pub b: f32,
    pub c: f32,
    pub opacity: f32,
    pub depth: f32,
    pub color: Vec3,
}

impl Splat2d {
    #[inline(always)]
    pub fn load(p: &Projected, g: usize) -> Self {
        let m = p.means2d[g];
        let k = p.conics[g];
        Splat2d {
            mx: m.x,
            my: m.y,
            a: k.x,
            b: k.y,
            c: k.z,
            opacity: p.opacities[g],
            depth: p.depths[g],
            color: p.colors[g],
        }
    }
}

/// Pixel-centre offsets within a tile, `i + 0.5` for column or row `i`: a table, so the blend
/// loops convert no integers (the same bits as `origin + i as f32 + 0.5`).
pub(crate) const CENTRES: [f32; TS] = {
    let mut c = [0.5f32; TS];
    let mut i = 0;
    while i < TS {
        c[i] = i as f32 + 0.5;
        i += 1;
    }
    c
};

/// Per half of a tile row (pixels 0..8 and 8..16), each lane's `d = mean.x - x` for a Gaussian
/// over the tile whose left edge is `ox`: the same for every row it covers.
#[inline(always)]
pub(crate) fn lane_offsets(sp: &Splat2d, ox: f32) -> [[f32; LANES]; 2] {
    let mut d = [[0.0f32; LANES]; 2];
    for (h, half) in d.iter_mut().enumerate() {
        for (l, dl) in half.iter_mut().enumerate() {
            *dl = sp.mx - (ox + CENTRES[h * LANES + l]);
        }
    }
    d
}

/// What every row segment of one intersection shares for its falloff, scaled by log2(e) and
/// negated: per half row the lanes' `d` and `-a d² / 2`, and the conic's other two terms. Once
/// per intersection, so a segment adds only its row's terms.
pub(crate) struct RowTerms {
    d: [[f32; LANES]; 2],
    neg_quad: [[f32; LANES]; 2],
    neg_b: f32,
    neg_c_half: f32,
    opacity: f32,
}

impl RowTerms {
    #[inline(always)]
    pub fn new(sp: &Splat2d, ox: f32) -> Self {
        let d = lane_offsets(sp, ox);
        let neg_a_half = -0.5 * LOG2_E * sp.a;
        let mut neg_quad = [[0.0f32; LANES]; 2];
        for h in 0..2 {
            for l in 0..LANES {
                neg_quad[h][l] = neg_a_half * d[h][l] * d[h][l];
            }
        }
        RowTerms {
            d,
            neg_quad,
            neg_b: -LOG2_E * sp.b,
            neg_c_half: -0.5 * LOG2_E * sp.c,
            opacity: sp.opacity,
        }
    }
}

/// Per lane of the row segment `half` (0 or 1) at vertical offset `dy = mean.y - y`: the clamped
/// alpha, and `exp(-power)` where the pixel passes gsplat's `sigma < 0 || alpha < 1/255` skip,
/// -1 where it does not. The forward stores the latter for the backward to replay
/// ([`replay_falloff`]), so both take identical decisions bit for bit.
#[inline(always)]
pub(crate) fn falloff<F: Arith>(
    terms: &RowTerms,
    half: usize,
    dy: f32,
    alpha_max: f32,
    alpha_threshold: f32,
    alpha: &mut [f32; LANES],
    stored: &mut [f32; LANES],
) {
    // -sigma · log2(e) = d (-b' dy) + (-a' d² / 2 - c' dy² / 2): one add and one multiply-add
    // per lane on the chain the segment waits on.
    let neg_b_dy = terms.neg_b * dy;
    let neg_c_dy2_half = terms.neg_c_half * dy * dy;
    let (d, neg_quad) = (&terms.d[half], &terms.neg_quad[half]);
    for l in 0..LANES {
        let neg_sigma = F::mul_add(d[l], neg_b_dy, neg_quad[l] + neg_c_dy2_half);
        // The opacity is folded into the power of two beside the polynomial, off its chain.
        let (mantissa, scale) = exp2_parts::<F>(neg_sigma);
        let e = mantissa * scale;
        let raw = mantissa * (scale * terms.opacity);
        let al = if raw < alpha_max { raw } else { alpha_max };
        alpha[l] = al;
        stored[l] = if neg_sigma <= 0.0 && al >= alpha_threshold {
            e
        } else {
            -1.0
        };
    }
}

/// [`falloff`] replayed from the values the forward stored for a segment: `exp(-power)` where
/// the pixel passed the skip test, -1 where it did not. The same decisions as `falloff` without
/// a second exponential (the backward's longest dependency chain).
#[inline(always)]
pub(crate) fn replay_falloff(
    opacity: f32,
    stored: &[f32; LANES],
    alpha_max: f32,
    vis: &mut [f32; LANES],
    raw_alpha: &mut [f32; LANES],
    alpha: &mut [f32; LANES],
    ok: &mut [bool; LANES],
) {
    for l in 0..LANES {
        let e = stored[l];
        let raw = opacity * e;
        vis[l] = e;
        raw_alpha[l] = raw;
        alpha[l] = if raw < alpha_max { raw } else { alpha_max };
        ok[l] = e >= 0.0;
    }
}

/// Blends one tile into its planar state slice (`state_channels(L) * 256` floats).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn rasterize_tile_impl<F: Arith>(
    tile: usize,
    state: &mut [f32],
    masks: &mut [u32],
    seg_vis: &mut [f32],
    splats: &[Splat2d],
    isect_labels: &[f32],
    bins: &TileBins,
    labels: usize,
    alpha_max: f32,
    alpha_threshold: f32,
) {
    let tx = tile % bins.tiles_x as usize;
    let ty = tile / bins.tiles_x as usize;
    let (ox, oy) = ((tx * TS) as f32, (ty * TS) as f32);
    state.fill(0.0);
    let (t_buf, rest) = state.split_at_mut(TILE_PIXELS);
    start_transmittance(t_buf, bins.tile_extent(tile), bins.tile_pixel_rows(tile));
    let (rgb, rest) = rest.split_at_mut(3 * TILE_PIXELS);
    let (depth_buf, label_buf) = rest.split_at_mut(TILE_PIXELS);
    let (r_buf, gb) = rgb.split_at_mut(TILE_PIXELS);
    let (g_buf, b_buf) = gb.split_at_mut(TILE_PIXELS);
    // A finished pixel keeps its transmittance negated, so "live" is `t > 0` and the blend loop
    // works on floats only (a separate bool array costs more in mask conversions than the blend).
    let [start, end] = bins.tile_ranges[tile];
    // Per segment of the current intersection (at most 32): its falloff.
    let mut seg_alpha = [[0.0f32; LANES]; 2 * TS];
    let mut seg_stored = [[0.0f32; LANES]; 2 * TS];
    let mut w = [0.0f32; LANES];
    let mut vis_pos = 0;
    let ids = &bins.gaussian_ids[start as usize..end as usize];
    // Bit `2y + h` set while row segment (y, h) has a pixel still blending: a segment whose
    // pixels all finished is skipped before its falloff is computed, and the tile stops when
    // none is left.
    let mut live = live_segments(t_buf);
    let mut n = 0;
    while n < ids.len() {
        if live == 0 {
            break;
        }
        let sp = splats[n];
        let label_values = &isect_labels[n * labels..(n + 1) * labels];
        let todo = masks[n] & live;
        if todo == 0 {
            // Only over finished segments (or pixels outside the rendered ones): nothing to
            // blend or replay.
            masks[n] = 0;
            n += 1;
            continue;
        }
        let terms = RowTerms::new(&sp, ox);
        // Two passes over the segments: first every falloff (independent of the tile state, so
        // the out-of-order core overlaps their exp chains), then the blends.
        let count = todo.count_ones() as usize;
        let mut bits = todo;
        for k in 0..count {
            let s = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let dy = sp.my - (oy + CENTRES[s / 2]);
            falloff::<F>(
                &terms,
                s % 2,
                dy,
                alpha_max,
                alpha_threshold,
                &mut seg_alpha[k],
                &mut seg_stored[k],
            );
        }
        // The segments where some lane blended or stopped: the only ones the backward replays.
        let mut used = 0u32;
        let mut bits = todo;
        for k in 0..count {
            let s = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let base = (s / 2) * TS + (s % 2) * LANES;
            let t_seg: &mut [f32; LANES] = (&mut t_buf[base..base + LANES])
                .try_into()
                .expect("8 lanes");
            let alpha = &seg_alpha[k];
            let stored_k = &seg_stored[k];
            let mut any_valid = false;
            let mut any_stop = false;
            for l in 0..LANES {
                let t = t_seg[l];
                let valid = (t > 0.0) & (stored_k[l] >= 0.0);
                any_valid |= valid;
                let next_t = t * (1.0 - alpha[l]);
                // gsplat: `if (next_T <= 1e-4) { done = true; break; }` (exclusive).
                let stop = valid & (next_t <= TRANSMITTANCE_MIN);
                any_stop |= stop;
                let contrib = valid & !stop;
                w[l] = if contrib { alpha[l] * t } else { 0.0 };
                t_seg[l] = if contrib {
                    next_t
                } else if stop {
                    -t
                } else {
                    t
                };
            }
            if !any_valid {
                continue;
            }
            if any_stop && !any_live(t_seg) {
                live &= !(1 << s);
            }
            used |= 1 << s;
            let stored: &mut [f32; LANES] = (&mut seg_vis[vis_pos..vis_pos + LANES])
                .try_into()
                .expect("8 lanes");
            vis_pos += LANES;
            *stored = *stored_k;
            for l in 0..LANES {
                r_buf[base + l] = F::mul_add(w[l], sp.color.x, r_buf[base + l]);
                g_buf[base + l] = F::mul_add(w[l], sp.color.y, g_buf[base + l]);
                b_buf[base + l] = F::mul_add(w[l], sp.color.z, b_buf[base + l]);
                depth_buf[base + l] = F::mul_add(w[l], sp.depth, depth_buf[base + l]);
            }
            for (c, &p) in label_values.iter().enumerate() {
                let seg = &mut label_buf[c * TILE_PIXELS + base..c * TILE_PIXELS + base + LANES];
                for l in 0..LANES {
                    seg[l] = F::mul_add(w[l], p, seg[l]);
                }
            }
        }
        masks[n] = used;
        n += 1;
    }
    // Gaussians behind a finished tile: nothing to replay.
    masks[n..].fill(0);
    for t in t_buf.iter_mut() {
        *t = t.abs();
    }
}

/// Fills a tile's transmittance for the blend: 1 for its pixels in the image (`columns × rows`
/// of them, [`TileBins::tile_extent`]) and among the rendered pixels (`pixel_rows`, bit `x` of
/// row `y`; None: all), finished (negated) for the others (past the image's right or bottom
/// edge, or outside a loss region), so they neither blend nor keep the tile alive: a segment
/// with no live pixel is never visited. Forward and backward start alike.
#[inline(always)]
pub(crate) fn start_transmittance(
    t: &mut [f32],
    (columns, rows): (usize, usize),
    pixel_rows: Option<&[u16]>,
) {
    for (y, row) in t.chunks_exact_mut(TS).enumerate() {
        let bits = pixel_rows.map_or(u16::MAX, |r| r[y]);
        for (x, t) in row.iter_mut().enumerate() {
            let on = x < columns && y < rows && (bits >> x) & 1 == 1;
            *t = if on { 1.0 } else { -1.0 };
        }
    }
}

/// The row segments of a tile's transmittance (finished pixels negated) with a pixel still
/// blending, as bit `2y + h` for pixels `8h..8h + 8` of row `y`.
#[inline(always)]
pub(crate) fn live_segments(t: &[f32]) -> u32 {
    t.chunks_exact(LANES)
        .enumerate()
        .fold(0, |bits, (s, seg)| bits | ((any_live(seg) as u32) << s))
}

/// Whether any pixel of a transmittance slice (finished pixels negated) is still blending.
#[inline(always)]
pub(crate) fn any_live(t: &[f32]) -> bool {
    t.iter().fold(false, |any, &t| any | (t > 0.0))
}

simd_dispatch!(
    /// [`rasterize_tile_impl`] with AVX2 (or AVX-512VL) where the CPU has it.
    rasterize_tile => rasterize_tile_impl::<Arith>(
        tile: usize,
        state: &mut [f32],
        masks: &mut [u32],
        seg_vis: &mut [f32],
        splats: &[Splat2d],
        isect_labels: &[f32],
        bins: &TileBins,
        labels: usize,
        alpha_max: f32,
        alpha_threshold: f32,
    )
);

/// Blends every tile (rayon over tiles) into the tile-major `state`, and leaves in `segments`
/// what the backward replays: per intersection the row segments it blended into, per tile
/// their lanes' falloffs for [`replay_falloff`].
pub(crate) fn rasterize(
    projected: &Projected,
    bins: &TileBins,
    labels: usize,
    settings: &RenderSettings,
    state: &mut Vec<f32>,
    segments: &mut SegmentStore,
) {
    let stride = state_channels(labels) * TILE_PIXELS;
    // Sized only: every tile zeroes its own slice first (`rasterize_tile_impl`).
    state.resize(bins.tile_count() * stride, 0.0);
    segments.prepare(projected, bins, labels, settings.alpha_threshold);
    state
        .par_chunks_mut(stride)
        .zip(segments.tiles_mut(bins))
        .enumerate()
        .for_each(|(tile, (st, parts))| {
            rasterize_tile(
                tile,
                st,
                parts.masks,
                parts.vis,
                parts.splats,
                parts.labels,
                bins,
                labels,
                settings.alpha_max,
                settings.alpha_threshold,
            )
        });
}

/// Copies the tile-major state into the row-major output, compositing the background.
pub(crate) fn write_output(
    state: &[f32],
    bins: &TileBins,
    labels: usize,
    background: Vec3,
    width: u32,
    height: u32,
    out: &mut RenderOutput,
) {
    let (w, h) = (width as usize, height as usize);
    out.width = width;
    out.height = height;
    out.label_channels = labels;
    out.color.clear();
    out.color.resize(w * h * 3, 0.0);
    out.alpha.clear();
    out.alpha.resize(w * h, 0.0);
    out.depth.clear();
    out.depth.resize(w * h, 0.0);
    out.labels.clear();
    out.labels.resize(w * h * labels, 0.0);
    let stride = state_channels(labels) * TILE_PIXELS;
    let tiles_x = bins.tiles_x as usize;
    let bg = [background.x, background.y, background.z];
    for y in 0..h {
        let (ty, iy) = (y / TS, y % TS);
        // One tile's slice per 16 pixels of the row, not one lookup per pixel.
        for tx in 0..tiles_x {
            let st = &state[(ty * tiles_x + tx) * stride..][..stride];
            for ix in 0..TS.min(w - tx * TS) {
                let p = iy * TS + ix;
                let pixel = y * w + tx * TS + ix;
                let t = st[CH_T * TILE_PIXELS + p];
                for c in 0..3 {
                    out.color[pixel * 3 + c] = st[(CH_RGB + c) * TILE_PIXELS + p] + t * bg[c];
                }
                out.alpha[pixel] = 1.0 - t;
                out.depth[pixel] = st[CH_DEPTH * TILE_PIXELS + p];
                for k in 0..labels {
                    out.labels[pixel * labels + k] = st[(CH_LABELS + k) * TILE_PIXELS + p];
                }
            }
        }
    }
}
