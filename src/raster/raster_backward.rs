//! Rasterize backward: per tile, replay the forward blend front to back (the segments and
//! falloffs the forward stored, so the same decisions bit for bit) and accumulate each
//! intersection's screen-space gradients; then reduce them per Gaussian serially, so results
//! are identical for any thread count. It must not project.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::bin::TileBins;
use super::forward::{
    CENTRES, CH_DEPTH, CH_LABELS, CH_RGB, CH_T, LANES, Splat2d, lane_offsets, replay_falloff,
    start_transmittance, state_channels,
};
use super::segments::{SegmentStore, resize_for_overwrite};
use super::{
    MAX_LABEL_CHANNELS, PixelGrads, Projected, RenderSettings, ScreenGrads, TILE_PIXELS, TILE_SIZE,
    TRANSMITTANCE_MIN,
};
use crate::simd::{Arith, simd_dispatch};

const TS: usize = TILE_SIZE as usize;

/// Gradient slots per intersection / Gaussian: mean2d (2), conic (3), opacity, RGB, depth, labels.
pub(crate) fn grad_stride(labels: usize) -> usize {
    G_LABELS + labels
}
const G_MEAN: usize = 0;
const G_CONIC: usize = 2;
const G_OPACITY: usize = 5;
const G_RGB: usize = 6;
const G_DEPTH: usize = 9;
const G_LABELS: usize = 10;

/// Per-pixel inputs of one tile, gathered from the row-major gradients.
struct TileInputs {
    /// dL/d(R, G, B, depth) per pixel.
    v_chan: [[f32; TILE_PIXELS]; 4],
    v_labels: [[f32; TILE_PIXELS]; MAX_LABEL_CHANNELS],
    /// `sum_k C_k g_k` over every blended channel (background excluded), less what the final
    /// transmittance is worth, `T_final · (v_alpha - background · v_rgb)`: the replay subtracts
    /// its running prefix from this to get what lies behind each Gaussian.
    behind: [f32; TILE_PIXELS],
}

#[allow(clippy::too_many_arguments)]
fn gather_inputs(
    tile: usize,
    bins: &TileBins,
    state: &[f32],
    labels: usize,
    background: Vec3,
    v_out: &PixelGrads,
    width: usize,
    height: usize,
    inputs: &mut TileInputs,
) {
    let tx = tile % bins.tiles_x as usize;
    let ty = tile / bins.tiles_x as usize;
    for p in 0..TILE_PIXELS {
        let (x, y) = (tx * TS + p % TS, ty * TS + p / TS);
        let t_final = state[CH_T * TILE_PIXELS + p];
        if x >= width || y >= height {
            for c in inputs.v_chan.iter_mut() {
                c[p] = 0.0;
            }
            for c in inputs.v_labels[..labels].iter_mut() {
                c[p] = 0.0;
            }
            inputs.behind[p] = 0.0;
            continue;
        }
        let pixel = y * width + x;
        let v_rgb = Vec3::from_slice(&v_out.color[pixel * 3..pixel * 3 + 3]);
        let v_depth = v_out.depth.map_or(0.0, |d| d[pixel]);
        let v_alpha = v_out.alpha.map_or(0.0, |a| a[pixel]);
        let mut dot = 0.0;
        for c in 0..3 {
            inputs.v_chan[c][p] = v_rgb[c];
            dot += state[(CH_RGB + c) * TILE_PIXELS + p] * v_rgb[c];
        }
        inputs.v_chan[3][p] = v_depth;
        dot += state[CH_DEPTH * TILE_PIXELS + p] * v_depth;
        for k in 0..labels {
            let v = v_out.labels.map_or(0.0, |l| l[pixel * labels + k]);
            inputs.v_labels[k][p] = v;
            dot += state[(CH_LABELS + k) * TILE_PIXELS + p] * v;
        }
        inputs.behind[p] = dot - t_final * (v_alpha - background.dot(v_rgb));
    }
}

/// Replays one tile and writes `grad_stride(L)` values per intersection of the tile.
/// `HAS_LABELS` false compiles the label sums out (their 512-byte accumulator was zeroed per
/// intersection even with no label channels).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn backward_tile_impl<F: Arith, const HAS_LABELS: bool>(
    tile: usize,
    out: &mut [f32],
    masks: &[u32],
    seg_vis: &[f32],
    splats: &[Splat2d],
    isect_labels: &[f32],
    bins: &TileBins,
    inputs: &TileInputs,
    labels: usize,
    alpha_max: f32,
) {
    let stride = grad_stride(labels);
    let labels = if HAS_LABELS { labels } else { 0 };
    let tx = tile % bins.tiles_x as usize;
    let ty = tile / bins.tiles_x as usize;
    let (ox, oy) = ((tx * TS) as f32, (ty * TS) as f32);
    let mut t_buf = [1.0f32; TILE_PIXELS];
    start_transmittance(
        &mut t_buf,
        bins.tile_extent(tile),
        bins.tile_pixel_rows(tile),
    );
    // Running `sum_{j <= i} w_j (c_j · g)` per pixel: the suffix `S_i · g` is total - prefix.
    let mut prefix = [0.0f32; TILE_PIXELS];
    // Finished pixels keep their transmittance negated, as in the forward.
    let [start, end] = bins.tile_ranges[tile];
    let (mut vis, mut raw, mut alpha) = ([0.0; LANES], [0.0; LANES], [0.0; LANES]);
    let mut ok = [false; LANES];
    let mut w = [0.0f32; LANES];
    let mut cg = [0.0f32; LANES];
    debug_assert_eq!(masks.len(), (end - start) as usize);
    let mut vis_pos = 0;
    for (n, &mask) in masks.iter().enumerate() {
        let isect_out = &mut out[n * stride..(n + 1) * stride];
        if mask == 0 {
            // Blended nowhere in the forward: no gradient.
            isect_out.fill(0.0);
            continue;
        }
        let sp = splats[n];
        let label_values = &isect_labels[n * labels..(n + 1) * labels];
        let lane_dx = lane_offsets(&sp, ox);
        let mut s_dx = [0.0f32; LANES];
        let mut s_dy = [0.0f32; LANES];
        let mut s_dxdx = [0.0f32; LANES];
        let mut s_dxdy = [0.0f32; LANES];
        let mut s_dydy = [0.0f32; LANES];
        let mut s_op = [0.0f32; LANES];
        let mut s_chan = [[0.0f32; LANES]; 4];
        let mut s_lab = [[0.0f32; LANES]; MAX_LABEL_CHANNELS];
        // Only the segments where the forward blended or stopped a pixel: every other one
        // would leave the replayed state and these sums unchanged.
        let mut todo = mask;
        while todo != 0 {
            let s = todo.trailing_zeros() as usize;
            todo &= todo - 1;
            let (y, half) = (s / 2, s % 2);
            let dy = sp.my - (oy + CENTRES[y]);
            let dy2 = dy * dy;
            {
                let base = y * TS + half * LANES;
                let dx = &lane_dx[half];
                let stored: &[f32; LANES] = seg_vis[vis_pos..vis_pos + LANES]
                    .try_into()
                    .expect("8 lanes");
                vis_pos += LANES;
                replay_falloff(
                    sp.opacity, stored, alpha_max, &mut vis, &mut raw, &mut alpha, &mut ok,
                );
                let seg = |a: &[f32; TILE_PIXELS]| -> [f32; LANES] {
                    a[base..base + LANES].try_into().expect("8 lanes")
                };
                let (vr, vg, vb, vd) = (
                    seg(&inputs.v_chan[0]),
                    seg(&inputs.v_chan[1]),
                    seg(&inputs.v_chan[2]),
                    seg(&inputs.v_chan[3]),
                );
                for l in 0..LANES {
                    let rg = F::mul_add(sp.color.y, vg[l], sp.color.x * vr[l]);
                    let rgb = F::mul_add(sp.color.z, vb[l], rg);
                    cg[l] = F::mul_add(sp.depth, vd[l], rgb);
                }
                for (k, &p) in label_values.iter().enumerate() {
                    let v = seg(&inputs.v_labels[k]);
                    for l in 0..LANES {
                        cg[l] = F::mul_add(p, v[l], cg[l]);
                    }
                }
                let behind = seg(&inputs.behind);
                let t_seg: &mut [f32; LANES] = (&mut t_buf[base..base + LANES])
                    .try_into()
                    .expect("8 lanes");
                let p_seg: &mut [f32; LANES] = (&mut prefix[base..base + LANES])
                    .try_into()
                    .expect("8 lanes");
                for l in 0..LANES {
                    let t = t_seg[l];
                    let valid = (t > 0.0) & ok[l];
                    let next_t = t * (1.0 - alpha[l]);
                    let stop = valid & (next_t <= TRANSMITTANCE_MIN);
                    let contrib = valid & !stop;
                    let wl = if contrib { alpha[l] * t } else { 0.0 };
                    w[l] = wl;
                    p_seg[l] = F::mul_add(wl, cg[l], p_seg[l]);
                    // dL/dalpha_i = T_i c_i·g - (S_i·g - T_final v_T) / (1 - a_i),
                    // S_i = sum_{j > i} c_j alpha_j T_j (each T_j already holds 1 - a_i).
                    let ra = 1.0 / (1.0 - alpha[l]);
                    let v_alpha = F::mul_add(t, cg[l], -((behind[l] - p_seg[l]) * ra));
                    // Clamped alpha has no gradient (gsplat: `opac * vis <= 0.999f`).
                    let m = contrib & (raw[l] <= alpha_max);
                    let v_sigma = if m { -raw[l] * v_alpha } else { 0.0 };
                    s_op[l] = if m {
                        F::mul_add(vis[l], v_alpha, s_op[l])
                    } else {
                        s_op[l]
                    };
                    let d = dx[l];
                    let v_sigma_d = v_sigma * d;
                    s_dx[l] += v_sigma_d;
                    s_dy[l] = F::mul_add(v_sigma, dy, s_dy[l]);
                    s_dxdx[l] = F::mul_add(v_sigma_d, d, s_dxdx[l]);
                    s_dxdy[l] = F::mul_add(v_sigma_d, dy, s_dxdy[l]);
                    s_dydy[l] = F::mul_add(v_sigma, dy2, s_dydy[l]);
                    t_seg[l] = if contrib {
                        next_t
                    } else if stop {
                        -t
                    } else {
                        t
                    };
                }
                for l in 0..LANES {
                    s_chan[0][l] = F::mul_add(w[l], vr[l], s_chan[0][l]);
                    s_chan[1][l] = F::mul_add(w[l], vg[l], s_chan[1][l]);
                    s_chan[2][l] = F::mul_add(w[l], vb[l], s_chan[2][l]);
                    s_chan[3][l] = F::mul_add(w[l], vd[l], s_chan[3][l]);
                }
                for (acc, v_label) in s_lab.iter_mut().zip(&inputs.v_labels).take(labels) {
                    let v = seg(v_label);
                    for l in 0..LANES {
                        acc[l] = F::mul_add(w[l], v[l], acc[l]);
                    }
                }
            }
        }
        let sum = |a: &[f32; LANES]| a.iter().sum::<f32>();
        let (sdx, sdy) = (sum(&s_dx), sum(&s_dy));
        // sigma = 0.5 (a dx² + c dy²) + b dx dy with dx = mean.x - px.
        isect_out[G_MEAN] = sp.a * sdx + sp.b * sdy;
        isect_out[G_MEAN + 1] = sp.b * sdx + sp.c * sdy;
        isect_out[G_CONIC] = 0.5 * sum(&s_dxdx);
        isect_out[G_CONIC + 1] = sum(&s_dxdy);
        isect_out[G_CONIC + 2] = 0.5 * sum(&s_dydy);
        isect_out[G_OPACITY] = sum(&s_op);
        for c in 0..3 {
            isect_out[G_RGB + c] = sum(&s_chan[c]);
        }
        isect_out[G_DEPTH] = sum(&s_chan[3]);
        for k in 0..labels {
            isect_out[G_LABELS + k] = sum(&s_lab[k]);
        }
    }
}

/// [`backward_tile_impl`] with the label sums compiled in only when there are label channels.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn backward_tile_kernel<F: Arith>(
    tile: usize,
    out: &mut [f32],
    masks: &[u32],
    seg_vis: &[f32],
    splats: &[Splat2d],
    isect_labels: &[f32],
    bins: &TileBins,
    inputs: &TileInputs,
    labels: usize,
    alpha_max: f32,
) {
    // One argument list for both instantiations.
    macro_rules! run {
        ($has_labels:literal) => {
            backward_tile_impl::<F, $has_labels>(
                tile,
                out,
                masks,
                seg_vis,
                splats,
                isect_labels,
                bins,
                inputs,
                labels,
                alpha_max,
            )
        };
    }
    if labels > 0 { run!(true) } else { run!(false) }
}

simd_dispatch!(
    /// [`backward_tile_kernel`] with AVX2 (or AVX-512VL) where the CPU has it.
    backward_tile => backward_tile_kernel::<Arith>(
        tile: usize,
        out: &mut [f32],
        masks: &[u32],
        seg_vis: &[f32],
        splats: &[Splat2d],
        isect_labels: &[f32],
        bins: &TileBins,
        inputs: &TileInputs,
        labels: usize,
        alpha_max: f32,
    )
);

/// Screen-space gradients per intersection (rayon over tiles), reduced per Gaussian into
/// `gauss_grads` (`grad_stride(L)` per Gaussian) in intersection order.
#[allow(clippy::too_many_arguments)]
pub(crate) fn rasterize_backward(
    projected: &Projected,
    bins: &TileBins,
    state: &[f32],
    segments: &SegmentStore,
    labels: usize,
    settings: &RenderSettings,
    v_out: &PixelGrads,
    width: u32,
    height: u32,
    isect_grads: &mut Vec<f32>,
    gauss_grads: &mut Vec<f32>,
) {
    let stride = grad_stride(labels);
    let n_isects = bins.gaussian_ids.len();
    // Not cleared: `backward_tile` writes every slot of every intersection.
    resize_for_overwrite(isect_grads, n_isects * stride);
    let slices = bins.split_by_tile(isect_grads, stride);
    let state_stride = state_channels(labels) * TILE_PIXELS;
    let (w, h) = (width as usize, height as usize);
    // One zeroed `TileInputs` (23 kB) per rayon job rather than per tile: `gather_inputs`
    // overwrites every slot a tile reads.
    let fresh_inputs = || {
        Box::new(TileInputs {
            v_chan: [[0.0; TILE_PIXELS]; 4],
            v_labels: [[0.0; TILE_PIXELS]; MAX_LABEL_CHANNELS],
            behind: [0.0; TILE_PIXELS],
        })
    };
    slices
        .into_par_iter()
        .enumerate()
        .for_each_init(fresh_inputs, |inputs, (tile, out)| {
            let [start, end] = bins.tile_ranges[tile];
            if start == end {
                return;
            }
            let inputs = &mut **inputs;
            let st = &state[tile * state_stride..(tile + 1) * state_stride];
            gather_inputs(
                tile,
                bins,
                st,
                labels,
                settings.background,
                v_out,
                w,
                h,
                inputs,
            );
            backward_tile(
                tile,
                out,
                &segments.masks[start as usize..end as usize],
                segments.tile_vis(tile),
                &segments.splats[start as usize..end as usize],
                &segments.labels[start as usize * labels..end as usize * labels],
                bins,
                inputs,
                labels,
                settings.alpha_max,
            );
        });
    let n = projected.radii.len();
    gauss_grads.clear();
    gauss_grads.resize(n * stride, 0.0);
    for (i, &g) in bins.gaussian_ids.iter().enumerate() {
        let g = g as usize;
        let src = &isect_grads[i * stride..(i + 1) * stride];
        for (d, s) in gauss_grads[g * stride..(g + 1) * stride]
            .iter_mut()
            .zip(src)
        {
            *d += s;
        }
    }
}

/// Splits the per-Gaussian gradient rows into [`ScreenGrads`].
pub(crate) fn unpack_screen_grads(
    gauss_grads: &[f32],
    n: usize,
    labels: usize,
    screen: &mut ScreenGrads,
) {
    unpack_rows(gauss_grads, 0..n, labels, screen);
}

/// [`unpack_screen_grads`] of the Gaussians `ids` only, in `ids` order.
pub(crate) fn unpack_screen_grads_of(
    gauss_grads: &[f32],
    ids: &[u32],
    labels: usize,
    screen: &mut ScreenGrads,
) {
    unpack_rows(gauss_grads, ids.iter().map(|&g| g as usize), labels, screen);
}

/// The gradient rows `rows` into `screen`, in that order.
fn unpack_rows(
    gauss_grads: &[f32],
    rows: impl Iterator<Item = usize>,
    labels: usize,
    screen: &mut ScreenGrads,
) {
    let stride = grad_stride(labels);
    screen.v_means2d.clear();
    screen.v_conics.clear();
    screen.v_colors.clear();
    screen.v_opacities.clear();
    screen.v_depths.clear();
    screen.v_labels.clear();
    for g in rows {
        let r = &gauss_grads[g * stride..(g + 1) * stride];
        screen.v_means2d.push(Vec2::new(r[G_MEAN], r[G_MEAN + 1]));
        screen
            .v_conics
            .push(Vec3::new(r[G_CONIC], r[G_CONIC + 1], r[G_CONIC + 2]));
        screen.v_opacities.push(r[G_OPACITY]);
        screen
            .v_colors
            .push(Vec3::new(r[G_RGB], r[G_RGB + 1], r[G_RGB + 2]));
        screen.v_depths.push(r[G_DEPTH]);
        screen
            .v_labels
            .extend_from_slice(&r[G_LABELS..G_LABELS + labels]);
    }
}
