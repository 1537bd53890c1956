//! The photometric training loss `(1-λ)·L1 + λ·(1-SSIM)` with its exact gradient, optionally
//! restricted to a per-pixel region (the label loss is `train::label_loss`). Pure functions over
//! buffers; no rendering.

use rayon::prelude::*;

use super::region_runs::RegionRuns;
use super::ssim::{RegionImages, RegionSsim, SsimWorkspace, ssim_with_grad};

/// Weight of the D-SSIM term (3DGS `lambda_dssim`).
pub const SSIM_LAMBDA: f32 = 0.2;

/// Reusable scratch for `photometric_loss`: after the first call at a size, no allocation.
#[derive(Default)]
pub struct LossWorkspace {
    ssim: SsimWorkspace,
    /// The SSIM of a sparse region, on pieces around its tiles.
    region_ssim: RegionSsim,
    /// Region-blended render `m·x + (1-m)·t` (only for a region the SSIM pieces would not
    /// save on).
    blended: Vec<f32>,
    /// Per-pixel weights `a_p = m_p / (3·Σm)` (as `blended`).
    weights: Vec<f32>,
    /// dSSIM/d(blended).
    v_ssim: Vec<f32>,
    /// Weighted L1 per pixel row, summed in order for a thread-independent result.
    row_sums: Vec<f64>,
    /// The region's pixels as runs per row.
    runs: RegionRuns,
}

impl LossWorkspace {
    pub fn new() -> LossWorkspace {
        LossWorkspace::default()
    }
}

/// The photometric loss of one view and its parts (L1 and SSIM as the weighted means).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhotometricLoss {
    pub loss: f32,
    pub l1: f32,
    pub ssim: f32,
}

/// `(1-λ)·L1 + λ·(1-SSIM)` of `rendered` against `target` (interleaved RGB, `width·height·3`),
/// writing `dLoss/dRendered` into `v_rendered` (overwritten).
///
/// With a `region` (per-pixel weights in [0, 1], binary in practice), both terms are averaged
/// over the region only, and SSIM is computed on `m·rendered + (1-m)·target`: outside pixels are
/// replaced by the target, so windows straddling the border compare against true values and the
/// exact gradient is zero outside the region. An empty region gives zero loss and gradient.
#[allow(clippy::too_many_arguments)]
pub fn photometric_loss(
    ws: &mut LossWorkspace,
    rendered: &[f32],
    target: &[f32],
    width: u32,
    height: u32,
    region: Option<&[f32]>,
    lambda: f32,
    v_rendered: &mut [f32],
) -> PhotometricLoss {
    let (w, h) = (width as usize, height as usize);
    let n = w * h;
    assert_eq!(rendered.len(), n * 3, "photometric_loss: rendered size");
    assert_eq!(target.len(), n * 3, "photometric_loss: target size");
    assert_eq!(v_rendered.len(), n * 3, "photometric_loss: gradient size");
    if let Some(m) = region {
        assert_eq!(m.len(), n, "photometric_loss: region size");
    }
    ws.row_sums.resize(h, 0.0);
    ws.v_ssim.resize(n * 3, 0.0);
    let Some(m) = region else {
        let ssim = ssim_with_grad(
            &mut ws.ssim,
            rendered,
            target,
            width,
            height,
            None,
            Some(&mut ws.v_ssim),
        );
        let uniform = 1.0 / (3.0 * n.max(1) as f32);
        let v_ssim = &ws.v_ssim;
        let row_w = w * 3;
        v_rendered
            .par_chunks_mut(row_w.max(1))
            .zip(ws.row_sums.par_iter_mut())
            .enumerate()
            .for_each(|(y, (v_row, row_sum))| {
                let span = PixelSpan {
                    first: y * w,
                    a_p: |_| uniform,
                    m_p: |_| 1.0,
                };
                *row_sum = l1_and_gradient(span, rendered, target, v_ssim, lambda, v_row, 0.0);
            });
        return combine(&ws.row_sums, lambda, ssim);
    };

    // A region: only its pixels (its runs) are visited; the rest get no gradient.
    ws.runs.rebuild(m, w, h);
    let mass = ws.runs.mass(m);
    if !(mass > 0.0) {
        v_rendered.fill(0.0);
        return PhotometricLoss::default();
    }
    // Per-pixel weights: the region normalised to sum 1/3 per channel.
    let scale = (1.0 / (3.0 * mass)) as f32;
    // The SSIM on the pieces around the region's pixels (`ssim::region`), unless they would
    // cover the whole image anyway; it sees `m·rendered + (1-m)·target`.
    let images = RegionImages {
        rendered,
        target,
        region: m,
        scale,
    };
    let pieces = ws
        .region_ssim
        .ssim_with_grad(images, &ws.runs, &mut ws.v_ssim);
    let ssim = match pieces {
        Some(ssim) => ssim,
        None => {
            ws.weights.clear();
            ws.weights.extend(m.iter().map(|&v| v * scale));
            ws.blended.resize(n * 3, 0.0);
            ws.blended
                .par_chunks_mut(3)
                .zip(rendered.par_chunks(3))
                .zip(target.par_chunks(3).zip(m.par_iter()))
                .for_each(|((b, x), (t, &mp))| {
                    for c in 0..3 {
                        b[c] = mp * x[c] + (1.0 - mp) * t[c];
                    }
                });
            ssim_with_grad(
                &mut ws.ssim,
                &ws.blended,
                target,
                width,
                height,
                Some(&ws.weights),
                Some(&mut ws.v_ssim),
            )
        }
    };

    // L1 and the combined gradient on the region's runs, row by row.
    v_rendered.fill(0.0);
    let (v_ssim, runs) = (&ws.v_ssim, &ws.runs);
    v_rendered
        .par_chunks_mut((w * 3).max(1))
        .zip(ws.row_sums.par_iter_mut())
        .enumerate()
        .for_each(|(y, (v_row, row_sum))| {
            let mut sum = 0.0f64;
            for &[x0, x1] in runs.row(y) {
                let span = PixelSpan {
                    first: y * w + x0,
                    a_p: |p| m[p] * scale,
                    m_p: |p| m[p],
                };
                let v_run = &mut v_row[x0 * 3..x1 * 3];
                // Carried across the runs: the same additions, in the same order, as over the
                // whole row (the pixels between add exact zeros).
                sum = l1_and_gradient(span, rendered, target, v_ssim, lambda, v_run, sum);
            }
            *row_sum = sum;
        });
    combine(&ws.row_sums, lambda, ssim)
}

/// Pixels `first, first + 1, …` of one row (as many as the gradient slice holds) with their L1
/// weight `a_p` and region weight `m_p`.
struct PixelSpan<A, M> {
    first: usize,
    a_p: A,
    m_p: M,
}

/// `sum` plus the weighted L1 of a span's pixels, added left to right, writing each lane's
/// gradient `(1-λ)·a_p·sign(d) - λ·m_p·dSSIM/dx` into `v` (the span's lanes).
fn l1_and_gradient<A: Fn(usize) -> f32, M: Fn(usize) -> f32>(
    span: PixelSpan<A, M>,
    rendered: &[f32],
    target: &[f32],
    v_ssim: &[f32],
    lambda: f32,
    v: &mut [f32],
    mut sum: f64,
) -> f64 {
    for (k, v) in v.chunks_exact_mut(3).enumerate() {
        let p = span.first + k;
        let (a_p, m_p) = ((span.a_p)(p), (span.m_p)(p));
        for (c, vc) in v.iter_mut().enumerate() {
            let i = p * 3 + c;
            let d = rendered[i] - target[i];
            sum += (a_p * d.abs()) as f64;
            // d|d|/dd = sign(d), 0 at 0 as torch defines it.
            let sign = if d > 0.0 {
                1.0
            } else if d < 0.0 {
                -1.0
            } else {
                0.0
            };
            *vc = (1.0 - lambda) * a_p * sign - lambda * m_p * v_ssim[i];
        }
    }
    sum
}

/// The loss from the rows' weighted L1 sums (added in row order) and the weighted SSIM.
fn combine(row_sums: &[f64], lambda: f32, ssim: f64) -> PhotometricLoss {
    let l1: f64 = row_sums.iter().sum();
    let loss = (1.0 - lambda as f64) * l1 + lambda as f64 * (1.0 - ssim);
    PhotometricLoss {
        loss: loss as f32,
        l1: l1 as f32,
        ssim: ssim as f32,
    }
}

/// Region weights from a binary mask (non-zero → 1), written into a reused buffer.
pub fn mask_weights(mask: &crate::scene::Mask, out: &mut Vec<f32>) {
    out.clear();
    out.extend(mask.data.iter().map(|&v| if v != 0 { 1.0 } else { 0.0 }));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::ssim::ssim_map;
    use crate::train::label_loss::{LabelLossParams, label_loss};

    fn image(n: usize, seed: u64) -> Vec<f32> {
        let mut rng = fastrand::Rng::with_seed(seed);
        (0..n).map(|_| rng.f32()).collect()
    }

    /// The photometric loss in f64, straight from its definition, for finite differences.
    fn reference_loss(x: &[f64], t: &[f64], w: usize, h: usize, region: Option<&[f64]>) -> f64 {
        let n = w * h;
        let ones = vec![1.0; n];
        let m = region.unwrap_or(&ones);
        let mass: f64 = m.iter().sum();
        let mut l1 = 0.0;
        let mut ssim = 0.0;
        for c in 0..3 {
            let xb: Vec<f64> = (0..n)
                .map(|p| m[p] * x[p * 3 + c] + (1.0 - m[p]) * t[p * 3 + c])
                .collect();
            let tc: Vec<f64> = (0..n).map(|p| t[p * 3 + c]).collect();
            let map = ssim_map(&xb, &tc, w, h);
            for p in 0..n {
                l1 += m[p] * (x[p * 3 + c] - t[p * 3 + c]).abs();
                ssim += m[p] * map[p];
            }
        }
        let lambda = SSIM_LAMBDA as f64;
        (1.0 - lambda) * l1 / (3.0 * mass) + lambda * (1.0 - ssim / (3.0 * mass))
    }

    /// Checks every gradient lane against central differences of the f64 reference.
    fn check_gradient(w: usize, h: usize, region: Option<&[f32]>, seed: u64) {
        let x = image(w * h * 3, seed);
        // Keep |x - t| away from 0 so the L1 kink never falls inside a difference step.
        let t: Vec<f32> = image(w * h * 3, seed + 1)
            .iter()
            .zip(&x)
            .map(|(&v, &xv)| if (v - xv).abs() < 0.01 { xv + 0.05 } else { v })
            .collect();
        let mut ws = LossWorkspace::new();
        let mut grad = vec![0.0; x.len()];
        let out = photometric_loss(
            &mut ws,
            &x,
            &t,
            w as u32,
            h as u32,
            region,
            SSIM_LAMBDA,
            &mut grad,
        );
        let xd: Vec<f64> = x.iter().map(|&v| v as f64).collect();
        let td: Vec<f64> = t.iter().map(|&v| v as f64).collect();
        let rd: Option<Vec<f64>> = region.map(|r| r.iter().map(|&v| v as f64).collect());
        let base = reference_loss(&xd, &td, w, h, rd.as_deref());
        assert!(
            (out.loss as f64 - base).abs() < 1e-5,
            "{} vs {base}",
            out.loss
        );
        let max = grad.iter().fold(0.0f32, |a, &g| a.max(g.abs())) as f64;
        let step = 1e-5;
        let mut worst = 0.0f64;
        for i in 0..x.len() {
            let mut xp = xd.clone();
            xp[i] += step;
            let mut xm = xd.clone();
            xm[i] -= step;
            let fd = (reference_loss(&xp, &td, w, h, rd.as_deref())
                - reference_loss(&xm, &td, w, h, rd.as_deref()))
                / (2.0 * step);
            worst = worst.max((grad[i] as f64 - fd).abs() / max);
            // f32 analytic vs f64 differences: worst measured 5.6e-7 of the largest lane (17×13).
            assert!(
                (grad[i] as f64 - fd).abs() <= 1e-5 * max,
                "lane {i}: analytic {} vs fd {fd} (max {max})",
                grad[i]
            );
        }
        eprintln!("photometric gradient {w}x{h}: worst |analytic - fd| / max lane = {worst:.2e}");
    }

    #[test]
    fn photometric_gradient_matches_finite_differences() {
        check_gradient(17, 13, None, 10);
        check_gradient(4, 3, None, 20); // smaller than the window: padding on every side
    }

    #[test]
    fn region_gradient_matches_finite_differences_and_is_zero_outside() {
        let (w, h) = (15usize, 12usize);
        let region: Vec<f32> = (0..w * h)
            .map(|p| {
                if (3..10).contains(&(p % w)) && p / w > 2 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        check_gradient(w, h, Some(&region), 30);
        let x = image(w * h * 3, 1);
        let t = image(w * h * 3, 2);
        let mut grad = vec![1.0; x.len()];
        let mut ws = LossWorkspace::new();
        photometric_loss(
            &mut ws,
            &x,
            &t,
            w as u32,
            h as u32,
            Some(&region),
            SSIM_LAMBDA,
            &mut grad,
        );
        for (p, &m) in region.iter().enumerate() {
            if m == 0.0 {
                assert_eq!(&grad[p * 3..p * 3 + 3], &[0.0; 3]);
            }
        }
    }

    /// A hull-like region: a slanted band two pixels wide and a block, in a 37×23 image.
    fn hull_region(w: usize, h: usize) -> Vec<f32> {
        (0..w * h)
            .map(|p| {
                let (x, y) = ((p % w) as i64, (p / w) as i64);
                let band = (x - y - 4).abs() <= 1;
                let block = (25..31).contains(&x) && (3..9).contains(&y);
                if band || block { 1.0 } else { 0.0 }
            })
            .collect()
    }

    #[test]
    fn region_runs_give_the_whole_crop_passes_bits() {
        // The plain reference: the L1 and the label loss over every pixel of the crop, as
        // before they walked the region's runs.
        let (w, h, channels) = (37usize, 23usize, 2usize);
        let n = w * h;
        let m = hull_region(w, h);
        let (x, t) = (image(n * 3, 11), image(n * 3, 12));
        let mass: f64 = m.iter().map(|&v| v as f64).sum();
        let scale = (1.0 / (3.0 * mass)) as f32;
        let mut l1 = 0.0f64;
        let mut v_plain = vec![0.0f32; n * 3];
        for y in 0..h {
            let mut row = 0.0f64;
            for px in 0..w {
                let p = y * w + px;
                let a_p = m[p] * scale;
                for c in 0..3 {
                    let d = x[p * 3 + c] - t[p * 3 + c];
                    row += (a_p * d.abs()) as f64;
                    v_plain[p * 3 + c] = a_p * d.signum() * if d == 0.0 { 0.0 } else { 1.0 };
                }
            }
            l1 += row;
        }
        // λ = 0: the gradient is the L1's alone.
        let mut v = vec![f32::NAN; n * 3];
        let got = photometric_loss(
            &mut LossWorkspace::new(),
            &x,
            &t,
            w as u32,
            h as u32,
            Some(&m),
            0.0,
            &mut v,
        );
        assert_eq!(got.l1.to_bits(), (l1 as f32).to_bits());
        for (i, (a, b)) in v.iter().zip(&v_plain).enumerate() {
            assert!(a == b, "lane {i}: {a} against {b}");
        }

        let labels = image(n * channels, 13);
        let masks: Vec<Vec<u8>> = (0..channels)
            .map(|k| (0..n).map(|p| u8::from((p + k) % 3 == 0)).collect())
            .collect();
        let params = LabelLossParams::default();
        let total = mass * channels as f64;
        let mut plain = 0.0f64;
        let mut v_plain = vec![0.0f32; n * channels];
        for p in 0..n {
            if m[p] == 0.0 {
                continue;
            }
            for k in 0..channels {
                let q = labels[p * channels + k].clamp(params.eps, 1.0 - params.eps);
                let scale = m[p] as f64 * (1.0 / total);
                if masks[k][p] != 0 {
                    plain -= scale * (params.pos_weight * q.ln()) as f64;
                    v_plain[p * channels + k] = (-(scale as f32) * params.pos_weight) / q;
                } else {
                    plain -= scale * (1.0 - q).ln() as f64;
                    v_plain[p * channels + k] = (scale as f32) / (1.0 - q);
                }
            }
        }
        let targets: Vec<Option<&[u8]>> = masks.iter().map(|m| Some(m.as_slice())).collect();
        let mut v = vec![f32::NAN; n * channels];
        let got = label_loss(&labels, channels, &targets, Some(&m), &params, &mut v);
        assert_eq!(got.to_bits(), (plain as f32).to_bits());
        assert!(
            v.iter()
                .zip(&v_plain)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
    }

    #[test]
    fn fast_ssim_matches_the_metric() {
        let (w, h) = (41u32, 29u32);
        let x = image((w * h * 3) as usize, 5);
        let t = image((w * h * 3) as usize, 6);
        let mut ws = SsimWorkspace::new();
        let fast = ssim_with_grad(&mut ws, &x, &t, w, h, None, None);
        let slow = crate::metrics::ssim(&x, &t, w, h);
        // f32 accumulation over an 11×11 window against f64: measured difference ~1e-7.
        assert!((fast - slow).abs() < 1e-5, "{fast} vs {slow}");
    }

    #[test]
    fn identical_images_give_zero_loss_and_gradient() {
        let x = image(20 * 10 * 3, 7);
        let mut grad = vec![1.0; x.len()];
        let out = photometric_loss(
            &mut LossWorkspace::new(),
            &x,
            &x,
            20,
            10,
            None,
            SSIM_LAMBDA,
            &mut grad,
        );
        assert!(out.loss.abs() < 1e-6 && out.l1 == 0.0, "{out:?}");
        assert!(grad.iter().all(|g| g.abs() < 1e-6));
    }

    #[test]
    fn workspace_reuse_across_sizes_gives_fresh_results() {
        let mut ws = LossWorkspace::new();
        let mut sizes = vec![(23u32, 11u32), (9, 30), (23, 11)];
        let mut results = Vec::new();
        for (i, (w, h)) in sizes.drain(..).enumerate() {
            let n = (w * h * 3) as usize;
            let (x, t) = (image(n, 40 + i as u64 % 2), image(n, 50 + i as u64 % 2));
            let mut g1 = vec![0.0; n];
            let mut g2 = vec![0.0; n];
            let a = photometric_loss(&mut ws, &x, &t, w, h, None, SSIM_LAMBDA, &mut g1);
            let b = photometric_loss(
                &mut LossWorkspace::new(),
                &x,
                &t,
                w,
                h,
                None,
                SSIM_LAMBDA,
                &mut g2,
            );
            assert_eq!(a, b);
            assert_eq!(g1, g2);
            results.push(a);
        }
        assert_eq!(results[0], results[2]);
    }

    #[test]
    fn empty_region_gives_zero_loss() {
        let x = image(8 * 8 * 3, 1);
        let t = image(8 * 8 * 3, 2);
        let mut grad = vec![1.0; x.len()];
        let region = vec![0.0; 64];
        let out = photometric_loss(
            &mut LossWorkspace::new(),
            &x,
            &t,
            8,
            8,
            Some(&region),
            SSIM_LAMBDA,
            &mut grad,
        );
        assert_eq!(out, PhotometricLoss::default());
        assert!(grad.iter().all(|&g| g == 0.0));
    }
}
