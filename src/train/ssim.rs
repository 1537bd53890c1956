//! Fast SSIM with its exact backward, as the training loss uses it: 3DGS's formulation (11×11
//! Gaussian window, σ = 1.5, per channel, zero 'same' padding like `conv2d(padding=5)`).
//! Separable, rayon over rows, allocation-free once a `SsimWorkspace` has seen a size.

use rayon::prelude::*;

/// Window side and radius (3DGS `window_size = 11`).
pub const SSIM_WINDOW: usize = 11;
const RADIUS: usize = SSIM_WINDOW / 2;
/// Gaussian window standard deviation in pixels (3DGS `create_window(11, 3)` uses σ = 1.5).
pub const SSIM_SIGMA: f32 = 1.5;
/// Stabilisers from the SSIM paper for a dynamic range of 1: (0.01·L)², (0.03·L)².
pub const SSIM_C1: f32 = 0.01 * 0.01;
pub const SSIM_C2: f32 = 0.03 * 0.03;

/// Forward maps per pixel: x, y, x², y², x·y (before blurring) and their blurred means.
const FWD: usize = 5;
/// Backward maps per pixel: dS/dmu_x, dS/dE[x²], dS/dE[xy] (before and after blurring).
const BWD: usize = 3;
/// Rows per rayon task: enough work per task that scheduling costs stay negligible.
const ROWS_PER_TASK: usize = 4;

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
/// Planes are indexed by "plane row" `r = channel * height + y`.
#[derive(Default)]
pub struct SsimWorkspace {
    width: usize,
    height: usize,
    kernel: [f32; SSIM_WINDOW],
    /// `FWD` maps per pixel, each row zero-padded by `RADIUS` pixels on both sides.
    fwd_padded: Vec<f32>,
    /// Horizontal blur of `fwd_padded`, unpadded.
    fwd_h: Vec<f32>,
    /// Blurred statistics: mu_x, mu_y, E[x²], E[y²], E[xy].
    stats: Vec<f32>,
    /// `BWD` weighted partial derivatives per pixel, padded like `fwd_padded`.
    bwd_padded: Vec<f32>,
    bwd_h: Vec<f32>,
    /// Blurred (adjoint-convolved) partials.
    bwd: Vec<f32>,
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
        self.fwd_padded = vec![0.0; rows * pw * FWD];
        self.fwd_h = vec![0.0; rows * width * FWD];
        self.stats = vec![0.0; rows * width * FWD];
        self.bwd_padded = vec![0.0; rows * pw * BWD];
        self.bwd_h = vec![0.0; rows * width * BWD];
        self.bwd = vec![0.0; rows * width * BWD];
        self.row_sums = vec![0.0; rows];
    }
}

/// Horizontal pass over a padded row of `m` interleaved maps: `out[i] = Σ_k g[k]·row[i + k·m]`.
#[inline]
fn blur_row(kernel: &[f32; SSIM_WINDOW], padded: &[f32], out: &mut [f32], m: usize) {
    let n = out.len();
    let first = &padded[..n];
    for (o, &p) in out.iter_mut().zip(first) {
        *o = kernel[0] * p;
    }
    for (k, &g) in kernel.iter().enumerate().skip(1) {
        let src = &padded[k * m..k * m + n];
        for (o, &p) in out.iter_mut().zip(src) {
            *o += g * p;
        }
    }
}

/// Horizontal then vertical blur of `m` maps, zero outside the image (the window is symmetric,
/// so the same operator is its own adjoint and serves the backward pass too).
fn blur_planes(
    kernel: &[f32; SSIM_WINDOW],
    width: usize,
    height: usize,
    m: usize,
    padded: &[f32],
    tmp: &mut [f32],
    out: &mut [f32],
) {
    let pw = (width + 2 * RADIUS) * m;
    let rw = width * m;
    tmp.par_chunks_mut(rw * ROWS_PER_TASK)
        .enumerate()
        .for_each(|(t, rows)| {
            for (i, row) in rows.chunks_mut(rw).enumerate() {
                let r = t * ROWS_PER_TASK + i;
                blur_row(kernel, &padded[r * pw..(r + 1) * pw], row, m);
            }
        });
    let tmp = &*tmp;
    out.par_chunks_mut(rw * ROWS_PER_TASK)
        .enumerate()
        .for_each(|(t, rows)| {
            for (i, row) in rows.chunks_mut(rw).enumerate() {
                let r = t * ROWS_PER_TASK + i;
                let (c, y) = (r / height, r % height);
                let plane = &tmp[c * height * rw..(c + 1) * height * rw];
                row.fill(0.0);
                for (k, &g) in kernel.iter().enumerate() {
                    let yy = y as isize + k as isize - RADIUS as isize;
                    if yy < 0 || yy >= height as isize {
                        continue;
                    }
                    let src = &plane[yy as usize * rw..(yy as usize + 1) * rw];
                    for (o, &p) in row.iter_mut().zip(src) {
                        *o += g * p;
                    }
                }
            }
        });
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
    let pwf = (w + 2 * RADIUS) * FWD;

    // 1. Per-pixel products, written between the zero pads.
    ws.fwd_padded
        .par_chunks_mut(pwf)
        .enumerate()
        .for_each(|(r, row)| {
            let (c, yy) = (r / h, r % h);
            let dst = &mut row[RADIUS * FWD..(RADIUS + w) * FWD];
            for (px, d) in dst.chunks_exact_mut(FWD).enumerate() {
                let i = (yy * w + px) * 3 + c;
                let (a, b) = (x[i], y[i]);
                d.copy_from_slice(&[a, b, a * a, b * b, a * b]);
            }
        });
    // 2. Local means of the five maps.
    blur_planes(
        &kernel,
        w,
        h,
        FWD,
        &ws.fwd_padded,
        &mut ws.fwd_h,
        &mut ws.stats,
    );
    // 3. The SSIM map, its weighted sum per row and the weighted partials w.r.t. the means.
    let want_grad = v_x.is_some();
    let pwb = (w + 2 * RADIUS) * BWD;
    let stats = &ws.stats;
    ws.bwd_padded
        .par_chunks_mut(pwb)
        .zip(ws.row_sums.par_iter_mut())
        .enumerate()
        .for_each(|(r, (row, row_sum))| {
            let yy = r % h;
            let srow = &stats[r * w * FWD..(r + 1) * w * FWD];
            let dst = &mut row[RADIUS * BWD..(RADIUS + w) * BWD];
            let mut sum = 0.0f64;
            for (px, (s, d)) in srow
                .chunks_exact(FWD)
                .zip(dst.chunks_exact_mut(BWD))
                .enumerate()
            {
                let a_p = pixel_weights.map_or(uniform, |a| a[yy * w + px]);
                let (mu_x, mu_y) = (s[0], s[1]);
                let var_x = s[2] - mu_x * mu_x;
                let var_y = s[3] - mu_y * mu_y;
                let cov = s[4] - mu_x * mu_y;
                let a1 = 2.0 * mu_x * mu_y + SSIM_C1;
                let a2 = 2.0 * cov + SSIM_C2;
                let b1 = mu_x * mu_x + mu_y * mu_y + SSIM_C1;
                let b2 = var_x + var_y + SSIM_C2;
                let inv = 1.0 / (b1 * b2);
                let ssim = a1 * a2 * inv;
                sum += (a_p * ssim) as f64;
                if want_grad {
                    // Partials holding the (co)variances fixed, then chained through
                    // var_x = E[x²] - mu_x², cov = E[xy] - mu_x·mu_y.
                    let d_mu = 2.0 * mu_y * a2 * inv - 2.0 * mu_x * ssim / b1;
                    let d_var = -ssim / b2;
                    let d_cov = 2.0 * a1 * inv;
                    d[0] = a_p * (d_mu - 2.0 * mu_x * d_var - mu_y * d_cov);
                    d[1] = a_p * d_var;
                    d[2] = a_p * d_cov;
                }
            }
            *row_sum = sum;
        });
    let total: f64 = ws.row_sums.iter().sum();
    let Some(v_x) = v_x else {
        return total;
    };
    assert_eq!(v_x.len(), n * 3, "ssim: gradient buffer size");
    // 4. Adjoint of the blur (the same blur), then through the products x, x², x·y.
    blur_planes(
        &kernel,
        w,
        h,
        BWD,
        &ws.bwd_padded,
        &mut ws.bwd_h,
        &mut ws.bwd,
    );
    let bwd = &ws.bwd;
    v_x.par_chunks_mut(w * 3).enumerate().for_each(|(yy, row)| {
        for c in 0..3 {
            let r = c * h + yy;
            let brow = &bwd[r * w * BWD..(r + 1) * w * BWD];
            for (px, b) in brow.chunks_exact(BWD).enumerate() {
                let i = px * 3 + c;
                let gi = (yy * w + px) * 3 + c;
                row[i] = b[0] + 2.0 * x[gi] * b[1] + y[gi] * b[2];
            }
        }
    });
    total
}
