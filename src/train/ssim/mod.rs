//! Fast SSIM with its exact backward, as the training loss uses it: 3DGS's formulation (11×11
//! Gaussian window, σ = 1.5, per channel, zero 'same' padding like `conv2d(padding=5)`).
//! Separable and streamed: per channel, each image row's products are blurred horizontally into
//! a ring of the last 11 rows, each SSIM row is blurred vertically from that ring as soon as its
//! window is complete, and its partials go through a second ring the same way, so every pass
//! works on rows that are still in the L1 cache. Rayon over horizontal bands (each recomputes
//! the 10 rows its windows reach beyond it; every value is computed the same way in any band,
//! so results are identical for any thread count), AVX2 or AVX-512 with fused multiply-adds
//! where the CPU has them, allocation-free once a `SsimWorkspace` has seen a size.

use rayon::prelude::*;

use crate::simd::{Arith, simd_dispatch};

/// Window side and radius (3DGS `window_size = 11`).
pub const SSIM_WINDOW: usize = 11;
const RADIUS: usize = SSIM_WINDOW / 2;
/// Gaussian window standard deviation in pixels (3DGS `create_window(11, 3)` uses σ = 1.5).
pub const SSIM_SIGMA: f32 = 1.5;
/// Stabilisers from the SSIM paper for a dynamic range of 1: (0.01·L)², (0.03·L)².
pub const SSIM_C1: f32 = 0.01 * 0.01;
pub const SSIM_C2: f32 = 0.03 * 0.03;

/// Forward maps: x, y, x², y², x·y (before blurring) and their blurred means.
const FWD: usize = 5;
/// Backward maps: dS/dmu_x, dS/dE[x²], dS/dE[xy] (before and after blurring).
const BWD: usize = 3;
/// Fewest image rows per band: below this the recomputed margins (10 rows on each side) would
/// cost more than the parallelism gains.
const MIN_BAND_ROWS: usize = 32;
/// Output columns a blur keeps in registers (one AVX vector of f32).
const LANES: usize = 8;

/// The normalised 1D Gaussian window (the 2D window is its outer product).
pub fn gaussian_window() -> [f32; SSIM_WINDOW] {
    let mut g = [0.0f32; SSIM_WINDOW];
    let mut sum = 0.0f64;
    for (i, v) in g.iter_mut().enumerate() {
        let d = i as f64 - RADIUS as f64;
        let e = (-(d * d) / (2.0 * (SSIM_SIGMA as f64).powi(2))).exp();
        *v = e as f32;
        sum += e;
    }
    for v in &mut g {
        *v = (*v as f64 / sum) as f32;
    }
    g
}

/// One band task's scratch, for images `width` wide: the current padded row of each map, the
/// rings of horizontally blurred rows (row `r` in slot `r % SSIM_WINDOW`), and one row of each
/// later stage.
#[derive(Clone, Default)]
struct BandScratch {
    /// `FWD` rows of `width + 2·RADIUS`, zero pads never written.
    fwd_padded: Vec<f32>,
    /// `FWD` rings of `SSIM_WINDOW` rows.
    fwd_ring: Vec<f32>,
    /// Blurred statistics of one row: mu_x, mu_y, E[x²], E[y²], E[xy].
    stats: Vec<f32>,
    /// Weighted SSIM of one row.
    ssim_row: Vec<f32>,
    /// `BWD` weighted partials of one row, padded like `fwd_padded`.
    bwd_padded: Vec<f32>,
    /// `BWD` rings of their horizontal blurs.
    bwd_ring: Vec<f32>,
    /// Blurred (adjoint-convolved) partials of one row.
    bwd_rows: Vec<f32>,
    /// Weighted SSIM sum per channel and row of the band (`3 × band rows`).
    sums: Vec<f64>,
}

impl BandScratch {
    /// Sizes every buffer for `width` and `band_rows`, all zero (the padding columns are never
    /// written afterwards), keeping the allocations: a workspace that serves regions of many
    /// sizes (`region.rs`) allocates only when one is larger than any before.
    fn reset(&mut self, width: usize, band_rows: usize) {
        let pw = width + 2 * RADIUS;
        fn zeros(v: &mut Vec<f32>, len: usize) {
            v.clear();
            v.resize(len, 0.0);
        }
        zeros(&mut self.fwd_padded, FWD * pw);
        zeros(&mut self.fwd_ring, FWD * SSIM_WINDOW * width);
        zeros(&mut self.stats, FWD * width);
        zeros(&mut self.ssim_row, width);
        zeros(&mut self.bwd_padded, BWD * pw);
        zeros(&mut self.bwd_ring, BWD * SSIM_WINDOW * width);
        zeros(&mut self.bwd_rows, BWD * width);
        self.sums.clear();
        self.sums.resize(3 * band_rows, 0.0);
    }
}

/// Scratch for `ssim_with_grad`, sized on first use and reused while the size and band count
/// hold.
#[derive(Default)]
pub struct SsimWorkspace {
    width: usize,
    height: usize,
    band_rows: usize,
    kernel: [f32; SSIM_WINDOW],
    bands: Vec<BandScratch>,
    /// Weighted SSIM sum per plane row `c · height + y`, summed in order for a
    /// thread-independent result.
    row_sums: Vec<f64>,
}

impl SsimWorkspace {
    pub fn new() -> SsimWorkspace {
        SsimWorkspace::default()
    }

    fn ensure(&mut self, width: usize, height: usize, band_rows: usize) {
        let bands = height.div_ceil(band_rows);
        if self.width == width
            && self.height == height
            && self.band_rows == band_rows
            && self.bands.len() == bands
        {
            return;
        }
        self.width = width;
        self.height = height;
        self.band_rows = band_rows;
        self.kernel = gaussian_window();
        // Zeroed buffers: the padding columns are never written afterwards.
        self.bands.resize_with(bands, BandScratch::default);
        for band in &mut self.bands {
            band.reset(width, band_rows);
        }
        self.row_sums.clear();
        self.row_sums.resize(3 * height, 0.0);
    }
}

/// `N` outputs of the horizontal pass from `src[..N + 2·RADIUS]`, taps added in order. `N`
/// independent accumulators: one would leave the adds waiting on each other's latency.
#[inline(always)]
fn hblur_block<F: Arith, const N: usize>(
    kernel: &[f32; SSIM_WINDOW],
    src: &[f32],
    out: &mut [f32],
) {
    let mut acc = [0.0f32; N];
    let first: &[f32; N] = src[..N].try_into().expect("block");
    for l in 0..N {
        acc[l] = kernel[0] * first[l];
    }
    for (k, &g) in kernel.iter().enumerate().skip(1) {
        let s: &[f32; N] = src[k..k + N].try_into().expect("block");
        for l in 0..N {
            acc[l] = F::mul_add(g, s[l], acc[l]);
        }
    }
    out[..N].copy_from_slice(&acc);
}

/// Horizontal pass of one padded row: `out[i] = Σ_k g[k]·src[i + k]`.
#[inline(always)]
fn hblur_row<F: Arith>(kernel: &[f32; SSIM_WINDOW], src: &[f32], out: &mut [f32]) {
    let width = out.len();
    let mut x = 0;
    while x + 4 * LANES <= width {
        hblur_block::<F, { 4 * LANES }>(kernel, &src[x..], &mut out[x..]);
        x += 4 * LANES;
    }
    while x + LANES <= width {
        hblur_block::<F, LANES>(kernel, &src[x..], &mut out[x..]);
        x += LANES;
    }
    if x < width && width >= LANES {
        // The last columns as one vector block overlapping the previous one (each column's
        // value does not depend on its block), instead of one column at a time: a single
        // accumulator waits on 11 multiply-adds in a row.
        let x = width - LANES;
        hblur_block::<F, LANES>(kernel, &src[x..], &mut out[x..]);
    } else {
        while x < width {
            hblur_block::<F, 1>(kernel, &src[x..], &mut out[x..]);
            x += 1;
        }
    }
}

/// `N` outputs of the vertical pass at column `x`: the taps `k` of `taps` (the source rows
/// inside the plane), whose rows start at `offsets[k]` in the ring, added in order from 0.
/// `FULL` (every tap inside) makes the tap count a constant, so the accumulators stay in
/// registers instead of going through the stack on every tap.
#[inline(always)]
fn vblur_block<F: Arith, const N: usize, const FULL: bool>(
    kernel: &[f32; SSIM_WINDOW],
    ring: &[f32],
    offsets: &[usize; SSIM_WINDOW],
    taps: std::ops::Range<usize>,
    x: usize,
    out: &mut [f32],
) {
    let taps = if FULL { 0..SSIM_WINDOW } else { taps };
    let mut acc = [0.0f32; N];
    for k in taps {
        let at = offsets[k] + x;
        let s: &[f32; N] = ring[at..at + N].try_into().expect("block");
        for l in 0..N {
            acc[l] = F::mul_add(kernel[k], s[l], acc[l]);
        }
    }
    out[x..x + N].copy_from_slice(&acc);
}

/// [`vblur_block`] over a whole row, in 32- and 8-column blocks.
#[inline(always)]
fn vblur_blocks<F: Arith, const FULL: bool>(
    kernel: &[f32; SSIM_WINDOW],
    ring: &[f32],
    offsets: &[usize; SSIM_WINDOW],
    taps: std::ops::Range<usize>,
    out: &mut [f32],
) {
    let width = out.len();
    let mut x = 0;
    while x + 4 * LANES <= width {
        vblur_block::<F, { 4 * LANES }, FULL>(kernel, ring, offsets, taps.clone(), x, out);
        x += 4 * LANES;
    }
    while x + LANES <= width {
        vblur_block::<F, LANES, FULL>(kernel, ring, offsets, taps.clone(), x, out);
        x += LANES;
    }
    if x < width && width >= LANES {
        // As in `hblur_row`: one overlapping vector block for the last columns.
        vblur_block::<F, LANES, FULL>(kernel, ring, offsets, taps, width - LANES, out);
    } else {
        while x < width {
            vblur_block::<F, 1, FULL>(kernel, ring, offsets, taps.clone(), x, out);
            x += 1;
        }
    }
}

/// Vertical pass: row `y` of a plane of `height` rows, zero outside it, from the ring holding
/// rows `y - RADIUS ..= y + RADIUS` (those inside the plane).
#[inline(always)]
fn vblur_row<F: Arith>(
    kernel: &[f32; SSIM_WINDOW],
    ring: &[f32],
    y: usize,
    height: usize,
    out: &mut [f32],
) {
    let width = out.len();
    let k_lo = RADIUS.saturating_sub(y);
    let k_hi = SSIM_WINDOW.min(height + RADIUS - y);
    let mut offsets = [0usize; SSIM_WINDOW];
    for (k, o) in offsets.iter_mut().enumerate().take(k_hi).skip(k_lo) {
        *o = ((y + k - RADIUS) % SSIM_WINDOW) * width;
    }
    if k_lo == 0 && k_hi == SSIM_WINDOW {
        vblur_blocks::<F, true>(kernel, ring, &offsets, k_lo..k_hi, out);
    } else {
        vblur_blocks::<F, false>(kernel, ring, &offsets, k_lo..k_hi, out);
    }
}

/// Horizontal pass of row `y` of every map, `width` values wide: `padded` holds one padded
/// row per map, `rings` one ring of `SSIM_WINDOW` rows per map; row `y` goes to slot
/// `y % SSIM_WINDOW`.
#[inline(always)]
fn hblur_into_ring<F: Arith>(
    kernel: &[f32; SSIM_WINDOW],
    padded: &[f32],
    width: usize,
    y: usize,
    rings: &mut [f32],
) {
    let slot = (y % SSIM_WINDOW) * width;
    let padded_rows = padded.chunks_exact(width + 2 * RADIUS);
    for (src, ring) in padded_rows.zip(rings.chunks_exact_mut(SSIM_WINDOW * width)) {
        hblur_row::<F>(kernel, src, &mut ring[slot..slot + width]);
    }
}

/// Vertical pass of row `y` (of `height`) of every map, `width` values wide, from their rings
/// (`SSIM_WINDOW` rows each) into `out` (one row per map).
#[inline(always)]
fn vblur_from_ring<F: Arith>(
    kernel: &[f32; SSIM_WINDOW],
    rings: &[f32],
    width: usize,
    y: usize,
    height: usize,
    out: &mut [f32],
) {
    let rows = out.chunks_exact_mut(width);
    for (ring, row) in rings.chunks_exact(SSIM_WINDOW * width).zip(rows) {
        vblur_row::<F>(kernel, ring, y, height, row);
    }
}

/// One row of step 3: the SSIM of each pixel from its blurred statistics (`stats[j]` is
/// map `j`'s row), its weighted sum, and (when `grads` is given) the weighted partials w.r.t.
/// the three means the SSIM depends on through x, written into the padded rows' interiors.
#[inline(always)]
fn partials_row(
    stats: [&[f32]; FWD],
    weights: Option<&[f32]>,
    uniform: f32,
    ssim_out: &mut [f32],
    grads: Option<[&mut [f32]; BWD]>,
) -> f64 {
    let [mu_x, mu_y, e_xx, e_yy, e_xy] = stats;
    let w = ssim_out.len();
    let weight = |px: usize| weights.map_or(uniform, |a| a[px]);
    match grads {
        Some([d_mu_out, d_var_out, d_cov_out]) => {
            let (d_mu_out, d_var_out, d_cov_out) =
                (&mut d_mu_out[..w], &mut d_var_out[..w], &mut d_cov_out[..w]);
            for px in 0..w {
                let a_p = weight(px);
                let (mx, my) = (mu_x[px], mu_y[px]);
                let var_x = e_xx[px] - mx * mx;
                let var_y = e_yy[px] - my * my;
                let cov = e_xy[px] - mx * my;
                let a1 = 2.0 * mx * my + SSIM_C1;
                let a2 = 2.0 * cov + SSIM_C2;
                let b1 = mx * mx + my * my + SSIM_C1;
                let b2 = var_x + var_y + SSIM_C2;
                let inv = 1.0 / (b1 * b2);
                let ssim = a1 * a2 * inv;
                ssim_out[px] = a_p * ssim;
                // Partials holding the (co)variances fixed, then chained through
                // var_x = E[x²] - mu_x², cov = E[xy] - mu_x·mu_y.
                let d_mu = 2.0 * my * a2 * inv - 2.0 * mx * ssim / b1;
                let d_var = -ssim / b2;
                let d_cov = 2.0 * a1 * inv;
                d_mu_out[px] = a_p * (d_mu - 2.0 * mx * d_var - my * d_cov);
                d_var_out[px] = a_p * d_var;
                d_cov_out[px] = a_p * d_cov;
            }
        }
        None => {
            for px in 0..w {
                let a_p = weight(px);
                let (mx, my) = (mu_x[px], mu_y[px]);
                let var_x = e_xx[px] - mx * mx;
                let var_y = e_yy[px] - my * my;
                let cov = e_xy[px] - mx * my;
                let a1 = 2.0 * mx * my + SSIM_C1;
                let a2 = 2.0 * cov + SSIM_C2;
                let b1 = mx * mx + my * my + SSIM_C1;
                let b2 = var_x + var_y + SSIM_C2;
                ssim_out[px] = a_p * (a1 * a2 * (1.0 / (b1 * b2)));
            }
        }
    }
    // In pixel order, in f64: the same sum on every path and thread count.
    ssim_out.iter().fold(0.0f64, |s, &v| s + v as f64)
}

/// What every band of one SSIM evaluation shares.
struct Frame<'a> {
    kernel: [f32; SSIM_WINDOW],
    /// Differentiated and target images, interleaved RGB.
    x: &'a [f32],
    y: &'a [f32],
    width: usize,
    height: usize,
    pixel_weights: Option<&'a [f32]>,
    uniform: f32,
}

/// Rows `y0..y1` of every channel: their weighted SSIM sums into `s.sums`, and with `v_rows`
/// (those rows of `dS/dx`, interleaved RGB) the gradient.
#[inline(always)]
fn band_impl<F: Arith>(
    f: &Frame,
    y0: usize,
    y1: usize,
    s: &mut BandScratch,
    mut v_rows: Option<&mut [f32]>,
) {
    let (w, h) = (f.width, f.height);
    let pw = w + 2 * RADIUS;
    let want_grad = v_rows.is_some();
    // SSIM rows whose partials the band's gradient rows reach, and the image rows their
    // windows reach: RADIUS beyond each.
    let (st_lo, st_hi) = if want_grad {
        (y0.saturating_sub(RADIUS), h.min(y1 + RADIUS))
    } else {
        (y0, y1)
    };
    let (in_lo, in_hi) = (st_lo.saturating_sub(RADIUS), h.min(st_hi + RADIUS));
    for c in 0..3 {
        let mut next_st = st_lo;
        let mut next_out = y0;
        for yi in in_lo..in_hi {
            // 1. Products of image row yi, then their horizontal blurs into the ring.
            {
                let at = yi * w * 3;
                let (xr, yr) = (&f.x[at..at + w * 3], &f.y[at..at + w * 3]);
                let (px_, rest) = s.fwd_padded.split_at_mut(pw);
                let (py_, rest) = rest.split_at_mut(pw);
                let (pxx, rest) = rest.split_at_mut(pw);
                let (pyy, pxy) = rest.split_at_mut(pw);
                let interior = RADIUS..RADIUS + w;
                let (px_, py_) = (&mut px_[interior.clone()], &mut py_[interior.clone()]);
                let (pxx, pyy) = (&mut pxx[interior.clone()], &mut pyy[interior.clone()]);
                let pxy = &mut pxy[interior];
                for p in 0..w {
                    let (a, b) = (xr[p * 3 + c], yr[p * 3 + c]);
                    px_[p] = a;
                    py_[p] = b;
                    pxx[p] = a * a;
                    pyy[p] = b * b;
                    pxy[p] = a * b;
                }
            }
            hblur_into_ring::<F>(&f.kernel, &s.fwd_padded, w, yi, &mut s.fwd_ring);
            // 2. Every SSIM row whose window the ring now holds.
            let last_in = yi + 1 == in_hi;
            while next_st < st_hi && (next_st + RADIUS <= yi || last_in) {
                let ys = next_st;
                next_st += 1;
                vblur_from_ring::<F>(&f.kernel, &s.fwd_ring, w, ys, h, &mut s.stats);
                // 3. Its SSIM and weighted partials.
                let stats: [&[f32]; FWD] = [
                    &s.stats[..w],
                    &s.stats[w..2 * w],
                    &s.stats[2 * w..3 * w],
                    &s.stats[3 * w..4 * w],
                    &s.stats[4 * w..],
                ];
                let weights = f.pixel_weights.map(|a| &a[ys * w..(ys + 1) * w]);
                let grads = if want_grad {
                    let (d_mu, rest) = s.bwd_padded.split_at_mut(pw);
                    let (d_var, d_cov) = rest.split_at_mut(pw);
                    let interior = RADIUS..RADIUS + w;
                    Some([
                        &mut d_mu[interior.clone()],
                        &mut d_var[interior.clone()],
                        &mut d_cov[interior],
                    ])
                } else {
                    None
                };
                let sum = partials_row(stats, weights, f.uniform, &mut s.ssim_row, grads);
                if (y0..y1).contains(&ys) {
                    s.sums[c * (y1 - y0) + ys - y0] = sum;
                }
                let Some(v_rows) = v_rows.as_deref_mut() else {
                    continue;
                };
                // 4. The partials' horizontal blurs into the second ring, then every gradient
                // row whose window it now holds: the adjoint of the blur (the same blur: the
                // window is symmetric), then through the products x, x², x·y.
                hblur_into_ring::<F>(&f.kernel, &s.bwd_padded, w, ys, &mut s.bwd_ring);
                let last_st = ys + 1 == st_hi;
                while next_out < y1 && (next_out + RADIUS <= ys || last_st) {
                    let yo = next_out;
                    next_out += 1;
                    vblur_from_ring::<F>(&f.kernel, &s.bwd_ring, w, yo, h, &mut s.bwd_rows);
                    let (b0, rest) = s.bwd_rows.split_at(w);
                    let (b1, b2) = rest.split_at(w);
                    let at = yo * w * 3;
                    let (xr, yr) = (&f.x[at..at + w * 3], &f.y[at..at + w * 3]);
                    let row = &mut v_rows[(yo - y0) * w * 3..(yo - y0 + 1) * w * 3];
                    for px in 0..w {
                        let i = px * 3 + c;
                        row[i] = b0[px] + 2.0 * xr[i] * b1[px] + yr[i] * b2[px];
                    }
                }
            }
        }
    }
}

simd_dispatch!(band => band_impl::<Arith>(
    f: &Frame,
    y0: usize,
    y1: usize,
    s: &mut BandScratch,
    v_rows: Option<&mut [f32]>,
));

/// Weighted SSIM `S = Σ_{p,c} a_p · ssim_{p,c}` of two interleaved RGB images and, when
/// `v_x` is given, its exact gradient `dS/dx` written (not added) into `v_x`.
///
/// `pixel_weights` are the `a_p` (length `width·height`); `None` means the plain mean,
/// `a_p = 1 / (3·width·height)`. `x` is the differentiated image, `y` the fixed target.
pub fn ssim_with_grad(
    ws: &mut SsimWorkspace,
    x: &[f32],
    y: &[f32],
    width: u32,
    height: u32,
    pixel_weights: Option<&[f32]>,
    v_x: Option<&mut [f32]>,
) -> f64 {
    // One band per thread: the fewest recomputed margin rows that still keeps every thread
    // busy. The band count changes no bit of the result.
    let bands = rayon::current_num_threads().max(1);
    let band_rows = (height as usize)
        .div_ceil(bands)
        .max(MIN_BAND_ROWS)
        .min(height as usize)
        .max(1);
    ssim_in_bands(ws, x, y, width, height, pixel_weights, v_x, band_rows)
}

/// [`ssim_with_grad`] with bands of `band_rows` image rows.
#[allow(clippy::too_many_arguments)]
fn ssim_in_bands(
    ws: &mut SsimWorkspace,
    x: &[f32],
    y: &[f32],
    width: u32,
    height: u32,
    pixel_weights: Option<&[f32]>,
    v_x: Option<&mut [f32]>,
    band_rows: usize,
) -> f64 {
    let (w, h) = (width as usize, height as usize);
    let n = w * h;
    assert_eq!(x.len(), n * 3, "ssim: rendered image size");
    assert_eq!(y.len(), n * 3, "ssim: target image size");
    if let Some(a) = pixel_weights {
        assert_eq!(a.len(), n, "ssim: pixel weight count");
    }
    if let Some(v) = &v_x {
        assert_eq!(v.len(), n * 3, "ssim: gradient buffer size");
    }
    if n == 0 {
        return 0.0;
    }
    ws.ensure(w, h, band_rows);
    let frame = Frame {
        kernel: ws.kernel,
        x,
        y,
        width: w,
        height: h,
        pixel_weights,
        uniform: 1.0 / (3.0 * n as f32),
    };
    let run = |(b, (s, v_rows)): (usize, (&mut BandScratch, Option<&mut [f32]>))| {
        let y0 = b * band_rows;
        band(&frame, y0, h.min(y0 + band_rows), s, v_rows);
    };
    match v_x {
        Some(v_x) => ws
            .bands
            .par_iter_mut()
            .zip(v_x.par_chunks_mut(band_rows * w * 3).map(Some))
            .enumerate()
            .for_each(run),
        None => ws
            .bands
            .par_iter_mut()
            .map(|s| (s, None))
            .enumerate()
            .for_each(run),
    }
    // Per plane row `c · h + y`, in that order, as one sequence: the same sum for any bands.
    for (b, s) in ws.bands.iter().enumerate() {
        let (y0, y1) = (b * band_rows, h.min((b + 1) * band_rows));
        for c in 0..3 {
            ws.row_sums[c * h + y0..c * h + y1]
                .copy_from_slice(&s.sums[c * (y1 - y0)..(c + 1) * (y1 - y0)]);
        }
    }
    ws.row_sums.iter().sum()
}

mod region;
pub use region::{RegionImages, RegionSsim};
#[cfg(test)]
mod tests;
