//! Rasterize forward: per 16×16 tile, blend its depth-sorted Gaussians front to back with the
//! 3DGS thresholds, in gsplat's exact order of tests. Gaussian-major over 8-pixel row segments
//! so the pixel loop vectorises; it must not project or sort.

use glam::Vec3;
use rayon::prelude::*;

use super::bin::TileBins;
use super::fast_exp::fast_exp;
use super::{Projected, RenderOutput, RenderSettings, TILE_PIXELS, TILE_SIZE, TRANSMITTANCE_MIN};

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
#[derive(Clone, Copy, Debug)]
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

/// The pixel rows `[y0, y1)` and columns `[x0, x1)` of a tile whose centres lie in a Gaussian's
/// extent box (`origin` is the tile's top-left pixel).
#[inline(always)]
pub(crate) fn footprint(p: &Projected, g: usize, ox: f32, oy: f32) -> [usize; 4] {
    let m = p.means2d[g];
    let e = p.extents[g];
    let ts = TS as f32;
    let lo = |v: f32| v.ceil().max(0.0).min(ts) as usize;
    let hi = |v: f32| (v.floor() + 1.0).max(0.0).min(ts) as usize;
    [
        lo(m.x - e.x - 0.5 - ox),
        lo(m.y - e.y - 0.5 - oy),
        hi(m.x + e.x - 0.5 - ox),
        hi(m.y + e.y - 0.5 - oy),
    ]
}

/// Row segments of a tile (row `y`, half `h`: pixels `8h..8h + 8`) whose pixel centres can
/// reach the alpha threshold, as bit `2y + h`: per row the chord of the ellipse
/// `power <= ln(opacity / threshold)`, padded, clipped to the footprint `[x0, y0, x1, y1]`.
/// Pixels outside it would be skipped by the blend loop anyway, so visiting only these changes
/// no result; it saves the work on the ellipse's rounded ends. All 16 rows at once so the
/// square roots and divisions vectorise instead of running one dependent chain per row.
#[inline(always)]
pub(crate) fn segment_mask(
    sp: &Splat2d,
    power_max: f32,
    [x0, y0, x1, y1]: [usize; 4],
    ox: f32,
    oy: f32,
) -> u32 {
    if x0 >= x1 || y0 >= y1 {
        return 0;
    }
    let ts = TS as f32;
    let (fx0, fx1) = (x0 as f32, x1 as f32);
    let mut lo = [fx0; TS];
    let mut hi = [fx1; TS];
    if power_max.is_finite() {
        for y in 0..TS {
            let dy = sp.my - (oy + y as f32 + 0.5);
            // 0.5 (a dx² + c dy²) + b dx dy <= P  <=>  a dx² + 2 b dy dx + c dy² - 2 P <= 0.
            let disc = sp.b * sp.b * dy * dy - sp.a * (sp.c * dy * dy - 2.0 * power_max);
            let root = disc.max(0.0).sqrt();
            let dx_lo = (-sp.b * dy - root) / sp.a;
            let dx_hi = (-sp.b * dy + root) / sp.a;
            // Pixel centre ox + x + 0.5 = mean.x - dx.
            let l = (sp.mx - dx_hi - 0.5 - ox - 0.05).ceil().max(0.0).min(ts);
            let h = ((sp.mx - dx_lo - 0.5 - ox + 0.05).floor() + 1.0)
                .max(0.0)
                .min(ts);
            // `!(disc >= 0)` also empties the row when disc is NaN.
            let empty = !(disc >= 0.0);
            lo[y] = if empty { ts } else { l.max(fx0) };
            hi[y] = if empty { 0.0 } else { h.min(fx1) };
        }
    }
    let lanes = LANES as f32;
    let mut bits = [0u32; TS];
    for y in 0..TS {
        let rows = y >= y0 && y < y1 && lo[y] < hi[y];
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

/// Per lane of a row segment starting at pixel-centre x `x0`: the offset `dx = mean.x - px`,
/// `exp(-power)`, the unclamped and clamped alpha, and whether the pixel passes gsplat's
/// `sigma < 0 || alpha < 1/255` skip. Forward and backward call this same code, so they take
/// identical decisions bit for bit.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn falloff(
    sp: &Splat2d,
    x0: f32,
    dy: f32,
    alpha_max: f32,
    alpha_threshold: f32,
    dx: &mut [f32; LANES],
    vis: &mut [f32; LANES],
    raw_alpha: &mut [f32; LANES],
    alpha: &mut [f32; LANES],
    ok: &mut [bool; LANES],
) {
    for l in 0..LANES {
        let d = sp.mx - (x0 + l as f32);
        let sigma = 0.5 * (sp.a * d * d + sp.c * dy * dy) + sp.b * d * dy;
        let e = fast_exp(-sigma);
        let raw = sp.opacity * e;
        let al = if raw < alpha_max { raw } else { alpha_max };
        dx[l] = d;
        vis[l] = e;
        raw_alpha[l] = raw;
        alpha[l] = al;
        ok[l] = sigma >= 0.0 && al >= alpha_threshold;
    }
}

/// Blends one tile into its planar state slice (`state_channels(L) * 256` floats).
#[inline(always)]
fn rasterize_tile_impl(
    tile: usize,
    state: &mut [f32],
    masks: &mut [u32],
    projected: &Projected,
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
    t_buf.fill(1.0);
    let (rgb, rest) = rest.split_at_mut(3 * TILE_PIXELS);
    let (depth_buf, label_buf) = rest.split_at_mut(TILE_PIXELS);
    let (r_buf, gb) = rgb.split_at_mut(TILE_PIXELS);
    let (g_buf, b_buf) = gb.split_at_mut(TILE_PIXELS);
    // A finished pixel keeps its transmittance negated, so "live" is `t > 0` and the blend loop
    // works on floats only (a separate bool array costs more in mask conversions than the blend).
    let [start, end] = bins.tile_ranges[tile];
    let mut dx = [0.0; LANES];
    let mut vis = [0.0; LANES];
    let mut raw = [0.0; LANES];
    let mut alpha = [0.0; LANES];
    let mut ok = [false; LANES];
    let mut w = [0.0f32; LANES];
    let ids = &bins.gaussian_ids[start as usize..end as usize];
    let mut n = 0;
    while n < ids.len() {
        if n % 32 == 31 && !any_live(t_buf) {
            break;
        }
        let g = ids[n] as usize;
        let sp = Splat2d::load(projected, g);
        let label_values = &projected.labels[g * labels..(g + 1) * labels];
        let power_max = power_limit(sp.opacity, alpha_threshold);
        let mut todo = segment_mask(&sp, power_max, footprint(projected, g, ox, oy), ox, oy);
        // The segments where some lane blended or stopped: the only ones the backward replays.
        let mut used = 0u32;
        while todo != 0 {
            let s = todo.trailing_zeros() as usize;
            todo &= todo - 1;
            let (y, half) = (s / 2, (s % 2) * LANES);
            let base = y * TS + half;
            let t_seg: &mut [f32; LANES] = (&mut t_buf[base..base + LANES])
                .try_into()
                .expect("8 lanes");
            if !any_live(t_seg) {
                continue;
            }
            let dy = sp.my - (oy + y as f32 + 0.5);
            falloff(
                &sp,
                ox + half as f32 + 0.5,
                dy,
                alpha_max,
                alpha_threshold,
                &mut dx,
                &mut vis,
                &mut raw,
                &mut alpha,
                &mut ok,
            );
            let mut any_valid = false;
            for l in 0..LANES {
                let t = t_seg[l];
                let valid = (t > 0.0) & ok[l];
                any_valid |= valid;
                let next_t = t * (1.0 - alpha[l]);
                // gsplat: `if (next_T <= 1e-4) { done = true; break; }` (exclusive).
                let stop = valid & (next_t <= TRANSMITTANCE_MIN);
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
            used |= 1 << s;
            for l in 0..LANES {
                r_buf[base + l] += w[l] * sp.color.x;
                g_buf[base + l] += w[l] * sp.color.y;
                b_buf[base + l] += w[l] * sp.color.z;
                depth_buf[base + l] += w[l] * sp.depth;
            }
            for (k, &p) in label_values.iter().enumerate() {
                let seg = &mut label_buf[k * TILE_PIXELS + base..k * TILE_PIXELS + base + LANES];
                for l in 0..LANES {
                    seg[l] += w[l] * p;
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

/// Whether any pixel of a transmittance slice (finished pixels negated) is still blending.
#[inline(always)]
pub(crate) fn any_live(t: &[f32]) -> bool {
    t.iter().fold(false, |any, &t| any | (t > 0.0))
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn rasterize_tile_avx2(
    tile: usize,
    state: &mut [f32],
    masks: &mut [u32],
    projected: &Projected,
    bins: &TileBins,
    labels: usize,
    alpha_max: f32,
    alpha_threshold: f32,
) {
    rasterize_tile_impl(
        tile,
        state,
        masks,
        projected,
        bins,
        labels,
        alpha_max,
        alpha_threshold,
    )
}

fn rasterize_tile(
    tile: usize,
    state: &mut [f32],
    masks: &mut [u32],
    projected: &Projected,
    bins: &TileBins,
    labels: usize,
    alpha_max: f32,
    alpha_threshold: f32,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        unsafe {
            rasterize_tile_avx2(
                tile,
                state,
                masks,
                projected,
                bins,
                labels,
                alpha_max,
                alpha_threshold,
            )
        };
        return;
    }
    rasterize_tile_impl(
        tile,
        state,
        masks,
        projected,
        bins,
        labels,
        alpha_max,
        alpha_threshold,
    )
}

/// Blends every tile (rayon over tiles) into the tile-major `state`, and writes per
/// intersection the mask of row segments it blended into (`segment_mask` bits) to `masks`.
pub(crate) fn rasterize(
    projected: &Projected,
    bins: &TileBins,
    labels: usize,
    settings: &RenderSettings,
    state: &mut Vec<f32>,
    masks: &mut Vec<u32>,
) {
    let stride = state_channels(labels) * TILE_PIXELS;
    state.clear();
    state.resize(bins.tile_count() * stride, 0.0);
    masks.clear();
    masks.resize(bins.gaussian_ids.len(), 0);
    let mask_slices = bins.split_by_tile(masks, 1);
    state
        .par_chunks_mut(stride)
        .zip(mask_slices)
        .enumerate()
        .for_each(|(tile, (st, m))| {
            rasterize_tile(
                tile,
                st,
                m,
                projected,
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
        for x in 0..w {
            let (tx, ix) = (x / TS, x % TS);
            let st = &state[(ty * tiles_x + tx) * stride..][..stride];
            let p = iy * TS + ix;
            let pixel = y * w + x;
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
