//! Fast SSIM with its exact backward, as the training loss uses it: 3DGS's formulation (11×11
//! Gaussian window, σ = 1.5, per channel, zero 'same' padding like `conv2d(padding=5)`).
//! Separable, planar (one contiguous plane per map, so every pass is a straight vector loop),
//! rayon over rows, AVX2 or AVX-512 with fused multiply-adds where the CPU has them,
//! allocation-free once a `SsimWorkspace` has seen a size.

use rayon::prelude::*;

use crate::simd::{MulAdd, simd_dispatch};

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
/// Rows per rayon task: enough work per task that scheduling costs stay negligible.
const ROWS_PER_TASK: usize = 4;
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

/// Scratch buffers for `ssim_with_grad`, sized on first use and reused while the size holds.
/// Each map is a plane of "plane rows" `r = channel * height + y`; map `j`'s row `r` is row
/// `j * 3 * height + r` of its buffer.
#[derive(Default)]
pub struct SsimWorkspace {
    width: usize,
    height: usize,
    kernel: [f32; SSIM_WINDOW],
    /// `FWD` maps, each row zero-padded by `RADIUS` pixels on both sides.
    fwd_padded: Vec<f32>,
    /// Horizontal blur of `fwd_padded`, unpadded.
    fwd_h: Vec<f32>,
    /// Blurred statistics: mu_x, mu_y, E[x²], E[y²], E[xy].
    stats: Vec<f32>,
    /// `BWD` weighted partial derivatives, padded like `fwd_padded`.
    bwd_padded: Vec<f32>,
    bwd_h: Vec<f32>,
    /// Blurred (adjoint-convolved) partials.
    bwd: Vec<f32>,
    /// Weighted SSIM per pixel, one row per plane row.
    ssim_map: Vec<f32>,
    /// Weighted SSIM sum per plane row, summed in order for a thread-independent result.
    row_sums: Vec<f64>,
}

impl SsimWorkspace {
    pub fn new() -> SsimWorkspace {
        SsimWorkspace::default()
    }

    fn ensure(&mut self, width: usize, height: usize) {
        if self.width == width && self.height == height && !self.fwd_h.is_empty() {
            return;
        }
        self.width = width;
        self.height = height;
        self.kernel = gaussian_window();
        let rows = 3 * height;
        let pw = width + 2 * RADIUS;
        // Fresh zeroed buffers: the padding columns are never written afterwards.
        self.fwd_padded = vec![0.0; FWD * rows * pw];
        self.fwd_h = vec![0.0; FWD * rows * width];
        self.stats = vec![0.0; FWD * rows * width];
        self.bwd_padded = vec![0.0; BWD * rows * pw];
        self.bwd_h = vec![0.0; BWD * rows * width];
        self.bwd = vec![0.0; BWD * rows * width];
        self.ssim_map = vec![0.0; rows * width];
        self.row_sums = vec![0.0; rows];
    }
}

/// `N` outputs of the horizontal pass from `src[..N + 2·RADIUS]`, taps added in order. `N`
/// independent accumulators: one would leave the adds waiting on each other's latency.
#[inline(always)]
fn hblur_block<F: MulAdd, const N: usize>(
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

/// Horizontal pass over padded rows: `out[i] = Σ_k g[k]·row[i + k]`.
#[inline(always)]
fn hblur_rows_impl<F: MulAdd>(
    kernel: &[f32; SSIM_WINDOW],
    padded: &[f32],
    out: &mut [f32],
    width: usize,
) {
    let pw = width + 2 * RADIUS;
    for (row, src) in out.chunks_exact_mut(width).zip(padded.chunks_exact(pw)) {
        let mut x = 0;
        while x + 4 * LANES <= width {
            hblur_block::<F, { 4 * LANES }>(kernel, &src[x..], &mut row[x..]);
            x += 4 * LANES;
        }
        while x + LANES <= width {
            hblur_block::<F, LANES>(kernel, &src[x..], &mut row[x..]);
            x += LANES;
        }
        if x < width && width >= LANES {
            // The last columns as one vector block overlapping the previous one (each column's
            // value does not depend on its block), instead of one column at a time: a single
            // accumulator waits on 11 multiply-adds in a row.
            let x = width - LANES;
            hblur_block::<F, LANES>(kernel, &src[x..], &mut row[x..]);
        } else {
            while x < width {
                hblur_block::<F, 1>(kernel, &src[x..], &mut row[x..]);
                x += 1;
            }
        }
    }
}

simd_dispatch!(hblur_rows => hblur_rows_impl::<MulAdd>(
    kernel: &[f32; SSIM_WINDOW],
    padded: &[f32],
    out: &mut [f32],
    width: usize,
));

/// `N` outputs of the vertical pass at column `x`: taps `k_lo..k_hi` (those whose source row
/// `y + k - RADIUS` lies inside the plane) added in order from 0.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn vblur_block<F: MulAdd, const N: usize>(
    kernel: &[f32; SSIM_WINDOW],
    plane: &[f32],
    width: usize,
    y: usize,
    k_lo: usize,
    k_hi: usize,
    x: usize,
    out: &mut [f32],
) {
    let mut acc = [0.0f32; N];
    for (k, &g) in kernel.iter().enumerate().take(k_hi).skip(k_lo) {
        let at = (y + k - RADIUS) * width + x;
        let s: &[f32; N] = plane[at..at + N].try_into().expect("block");
        for l in 0..N {
            acc[l] = F::mul_add(g, s[l], acc[l]);
        }
    }
    out[x..x + N].copy_from_slice(&acc);
}

/// Vertical pass: output rows `first..` of the stacked planes (`height` rows of `width` each)
/// from `src`, zero outside each plane.
#[inline(always)]
fn vblur_rows_impl<F: MulAdd>(
    kernel: &[f32; SSIM_WINDOW],
    src: &[f32],
    out: &mut [f32],
    first: usize,
    width: usize,
    height: usize,
) {
    for (i, row) in out.chunks_exact_mut(width).enumerate() {
        let r = first + i;
        let (plane, y) = (r / height, r % height);
        let plane = &src[plane * height * width..(plane + 1) * height * width];
        let k_lo = RADIUS.saturating_sub(y);
        let k_hi = SSIM_WINDOW.min(height + RADIUS - y);
        let mut x = 0;
        while x + 4 * LANES <= width {
            vblur_block::<F, { 4 * LANES }>(kernel, plane, width, y, k_lo, k_hi, x, row);
            x += 4 * LANES;
        }
        while x + LANES <= width {
            vblur_block::<F, LANES>(kernel, plane, width, y, k_lo, k_hi, x, row);
            x += LANES;
        }
        if x < width && width >= LANES {
            // As in `hblur_rows_impl`: one overlapping vector block for the last columns.
            vblur_block::<F, LANES>(kernel, plane, width, y, k_lo, k_hi, width - LANES, row);
        } else {
            while x < width {
                vblur_block::<F, 1>(kernel, plane, width, y, k_lo, k_hi, x, row);
                x += 1;
            }
        }
    }
}

simd_dispatch!(vblur_rows => vblur_rows_impl::<MulAdd>(
    kernel: &[f32; SSIM_WINDOW],
    src: &[f32],
    out: &mut [f32],
    first: usize,
    width: usize,
    height: usize,
));

/// Horizontal then vertical blur of stacked planes of `height` rows, zero outside each plane
/// (the window is symmetric, so the same operator is its own adjoint and serves the backward
/// pass too).
fn blur_planes(
    kernel: &[f32; SSIM_WINDOW],
    width: usize,
    height: usize,
    padded: &[f32],
    tmp: &mut [f32],
    out: &mut [f32],
) {
    let pw = width + 2 * RADIUS;
    tmp.par_chunks_mut(width * ROWS_PER_TASK)
        .enumerate()
        .for_each(|(t, rows)| {
            let first = t * ROWS_PER_TASK;
            let count = rows.len() / width;
            hblur_rows(
                kernel,
                &padded[first * pw..(first + count) * pw],
                rows,
                width,
            );
        });
    let tmp = &*tmp;
    out.par_chunks_mut(width * ROWS_PER_TASK)
        .enumerate()
        .for_each(|(t, rows)| {
            vblur_rows(kernel, tmp, rows, t * ROWS_PER_TASK, width, height);
        });
}

/// One plane row of step 3: the SSIM of each pixel from its blurred statistics (`stats[j]` is
/// map `j`'s row), its weighted sum, and (when `grads` is given) the weighted partials w.r.t.
/// the three means the SSIM depends on through x, written into the padded rows' interiors.
#[inline(always)]
fn partials_row_impl(
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

simd_dispatch!(partials_row => partials_row_impl(
    stats: [&[f32]; FWD],
    weights: Option<&[f32]>,
    uniform: f32,
    ssim_out: &mut [f32],
    grads: Option<[&mut [f32]; BWD]>,
) -> f64);

/// Map `j`'s plane row `r` of a buffer of `rows`-row planes of `len` floats per row.
fn map_row(buf: &[f32], j: usize, r: usize, rows: usize, len: usize) -> &[f32] {
    let at = (j * rows + r) * len;
    &buf[at..at + len]
}

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
    let (w, h) = (width as usize, height as usize);
    let n = w * h;
    assert_eq!(x.len(), n * 3, "ssim: rendered image size");
    assert_eq!(y.len(), n * 3, "ssim: target image size");
    if let Some(a) = pixel_weights {
        assert_eq!(a.len(), n, "ssim: pixel weight count");
    }
    if n == 0 {
        return 0.0;
    }
    ws.ensure(w, h);
    let kernel = ws.kernel;
    let uniform = 1.0 / (3.0 * n as f32);
    let rows = 3 * h;
    let pw = w + 2 * RADIUS;

    // 1. Per-pixel products, written between the zero pads of each map's row.
    {
        let mut maps = ws.fwd_padded.chunks_exact_mut(rows * pw);
        let mut next = || maps.next().expect("FWD planes").par_chunks_mut(pw);
        (next(), next(), next(), next(), next())
            .into_par_iter()
            .enumerate()
            .for_each(|(r, (px_, py_, pxx, pyy, pxy))| {
                let (c, yy) = (r / h, r % h);
                let interior = RADIUS..RADIUS + w;
                let (px_, py_) = (&mut px_[interior.clone()], &mut py_[interior.clone()]);
                let (pxx, pyy) = (&mut pxx[interior.clone()], &mut pyy[interior.clone()]);
                let pxy = &mut pxy[interior];
                let (xr, yr) = (
                    &x[yy * w * 3..(yy + 1) * w * 3],
                    &y[yy * w * 3..(yy + 1) * w * 3],
                );
                for p in 0..w {
                    let (a, b) = (xr[p * 3 + c], yr[p * 3 + c]);
                    px_[p] = a;
                    py_[p] = b;
                    pxx[p] = a * a;
                    pyy[p] = b * b;
                    pxy[p] = a * b;
                }
            });
    }
    // 2. Local means of the five maps.
    blur_planes(&kernel, w, h, &ws.fwd_padded, &mut ws.fwd_h, &mut ws.stats);
    // 3. The SSIM map, its weighted sum per row and the weighted partials w.r.t. the means.
    let want_grad = v_x.is_some();
    let stats = &ws.stats;
    {
        let mut maps = ws.bwd_padded.chunks_exact_mut(rows * pw);
        let mut next = || maps.next().expect("BWD planes").par_chunks_mut(pw);
        (next(), next(), next())
            .into_par_iter()
            .zip(ws.row_sums.par_iter_mut())
            .zip(ws.ssim_map.par_chunks_mut(w))
            .enumerate()
            .for_each(|(r, (((d_mu, d_var, d_cov), row_sum), ssim_row))| {
                let yy = r % h;
                let s = std::array::from_fn(|j| map_row(stats, j, r, rows, w));
                let weights = pixel_weights.map(|a| &a[yy * w..(yy + 1) * w]);
                let interior = RADIUS..RADIUS + w;
                let grads = want_grad.then(|| {
                    [
                        &mut d_mu[interior.clone()],
                        &mut d_var[interior.clone()],
                        &mut d_cov[interior.clone()],
                    ]
                });
                *row_sum = partials_row(s, weights, uniform, ssim_row, grads);
            });
    }
    let total: f64 = ws.row_sums.iter().sum();
    let Some(v_x) = v_x else {
        return total;
    };
    assert_eq!(v_x.len(), n * 3, "ssim: gradient buffer size");
    // 4. Adjoint of the blur (the same blur), then through the products x, x², x·y.
    blur_planes(&kernel, w, h, &ws.bwd_padded, &mut ws.bwd_h, &mut ws.bwd);
    let bwd = &ws.bwd;
    v_x.par_chunks_mut(w * 3).enumerate().for_each(|(yy, row)| {
        let (xr, yr) = (
            &x[yy * w * 3..(yy + 1) * w * 3],
            &y[yy * w * 3..(yy + 1) * w * 3],
        );
        for c in 0..3 {
            let r = c * h + yy;
            let [b0, b1, b2] = std::array::from_fn(|j| map_row(bwd, j, r, rows, w));
            for px in 0..w {
                let i = px * 3 + c;
                row[i] = b0[px] + 2.0 * xr[i] * b1[px] + yr[i] * b2[px];
            }
        }
    });
    total
}
