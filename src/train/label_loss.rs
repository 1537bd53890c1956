//! The label loss: weighted binary cross-entropy of rendered label channels (probabilities)
//! against per-class damage masks, optionally restricted to a per-pixel region, with its exact
//! gradient. A pure function over buffers, beside the photometric loss (`train::loss`).

use super::region_runs::RegionRuns;

/// Parameters of the label loss.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LabelLossParams {
    /// Weight of positive (damage) pixels; damage is rare, so values > 1 counter the imbalance.
    pub pos_weight: f32,
    /// Rendered probabilities are clamped to `[eps, 1 - eps]` before the logarithm.
    pub eps: f32,
}

impl Default for LabelLossParams {
    fn default() -> Self {
        LabelLossParams {
            pos_weight: 1.0,
            eps: 1e-4,
        }
    }
}

/// Weighted binary cross-entropy between blended label channels (`rendered[p·C + k]`, a
/// probability) and per-class masks (`targets[k]`, `width·height` values 0/1; `None` leaves
/// class `k` unsupervised), averaged over supervised (pixel, class) pairs, weighted by
/// `region`. Writes `dLoss/dRendered` into `v_labels` (overwritten; zero where unsupervised).
///
/// The probability is clamped to `[eps, 1-eps]`; the gradient is the BCE derivative at the
/// clamped value passed straight through the clamp, so a channel at exactly 0 (nothing blended
/// yet) is still pushed towards a positive mask instead of receiving the clamp's zero slope.
pub fn label_loss(
    rendered: &[f32],
    channels: usize,
    targets: &[Option<&[u8]>],
    region: Option<&[f32]>,
    params: &LabelLossParams,
    v_labels: &mut [f32],
) -> f32 {
    assert_eq!(
        targets.len(),
        channels,
        "label_loss: one target per channel"
    );
    assert_eq!(v_labels.len(), rendered.len(), "label_loss: gradient size");
    v_labels.fill(0.0);
    if channels == 0 {
        return 0.0;
    }
    let n = rendered.len() / channels;
    for t in targets.iter().flatten() {
        assert_eq!(t.len(), n, "label_loss: mask size");
    }
    if let Some(m) = region {
        assert_eq!(m.len(), n, "label_loss: region size");
    }
    let supervised = targets.iter().filter(|t| t.is_some()).count();
    // A region's pixels as runs of one row of `n`: only they are visited.
    let runs = region.map(|m| RegionRuns::of(m, n, 1));
    let mass: f64 = match (&runs, region) {
        (Some(runs), Some(m)) => runs.mass(m),
        _ => n as f64,
    };
    let total = mass * supervised as f64;
    if !(total > 0.0) {
        return 0.0;
    }
    let inv_total = 1.0 / total;
    let (pw, eps) = (params.pos_weight, params.eps);
    let mut loss = 0.0f64;
    let pixels: Box<dyn Iterator<Item = usize>> = match &runs {
        Some(runs) => Box::new(runs.pixels()),
        None => Box::new(0..n),
    };
    for p in pixels {
        let m = region.map_or(1.0, |m| m[p]);
        let r = &rendered[p * channels..(p + 1) * channels];
        let v = &mut v_labels[p * channels..(p + 1) * channels];
        for (k, target) in targets.iter().enumerate() {
            let Some(target) = target else { continue };
            let q = r[k].clamp(eps, 1.0 - eps);
            let scale = m as f64 * inv_total;
            if target[p] != 0 {
                loss -= scale * (pw * q.ln()) as f64;
                v[k] = (-(scale as f32) * pw) / q;
            } else {
                loss -= scale * (1.0 - q).ln() as f64;
                v[k] = (scale as f32) / (1.0 - q);
            }
        }
    }
    loss as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reference_bce(
        r: &[f64],
        c: usize,
        masks: &[Option<Vec<u8>>],
        region: &[f64],
        pw: f64,
    ) -> f64 {
        let n = r.len() / c;
        let sup = masks.iter().filter(|m| m.is_some()).count() as f64;
        let mass: f64 = region.iter().sum();
        let mut l = 0.0;
        for p in 0..n {
            for (k, m) in masks.iter().enumerate() {
                if let Some(m) = m {
                    let q = r[p * c + k];
                    let t = m[p] as f64;
                    l -= region[p] * (pw * t * q.ln() + (1.0 - t) * (1.0 - q).ln());
                }
            }
        }
        l / (mass * sup)
    }

    #[test]
    fn label_gradient_matches_finite_differences() {
        let (n, c) = (40usize, 3usize);
        let mut rng = fastrand::Rng::with_seed(9);
        let r: Vec<f32> = (0..n * c).map(|_| 0.05 + 0.9 * rng.f32()).collect();
        let masks: Vec<Option<Vec<u8>>> = vec![
            Some((0..n).map(|_| rng.u8(0..2)).collect()),
            None,
            Some((0..n).map(|_| rng.u8(0..2)).collect()),
        ];
        let region: Vec<f32> = (0..n).map(|p| if p % 5 == 0 { 0.0 } else { 1.0 }).collect();
        let params = LabelLossParams {
            pos_weight: 3.0,
            eps: 1e-4,
        };
        let targets: Vec<Option<&[u8]>> = masks.iter().map(|m| m.as_deref()).collect();
        let mut grad = vec![0.0; r.len()];
        let loss = label_loss(&r, c, &targets, Some(&region), &params, &mut grad);
        let rd: Vec<f64> = r.iter().map(|&v| v as f64).collect();
        let regd: Vec<f64> = region.iter().map(|&v| v as f64).collect();
        let base = reference_bce(&rd, c, &masks, &regd, 3.0);
        assert!((loss as f64 - base).abs() < 1e-5 * base.abs().max(1.0));
        for i in 0..r.len() {
            let step = 1e-6;
            let (mut rp, mut rm) = (rd.clone(), rd.clone());
            rp[i] += step;
            rm[i] -= step;
            let fd = (reference_bce(&rp, c, &masks, &regd, 3.0)
                - reference_bce(&rm, c, &masks, &regd, 3.0))
                / (2.0 * step);
            assert!(
                (grad[i] as f64 - fd).abs() < 1e-4 * fd.abs().max(1e-3),
                "lane {i}: {} vs {fd}",
                grad[i]
            );
        }
        assert!(
            grad.chunks(c).all(|g| g[1] == 0.0),
            "unsupervised class has no gradient"
        );
    }

    #[test]
    fn label_loss_pushes_an_empty_channel_towards_a_positive_mask() {
        let mut grad = vec![0.0; 2];
        let mask = [1u8, 0];
        label_loss(
            &[0.0, 0.0],
            1,
            &[Some(&mask)],
            None,
            &LabelLossParams::default(),
            &mut grad,
        );
        assert!(grad[0] < 0.0, "descent raises the positive pixel: {grad:?}");
        assert!(grad[1] > 0.0);
    }
}
