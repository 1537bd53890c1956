//! Image fidelity measures on interleaved RGB buffers with values in [0, 1].

/// Peak signal-to-noise ratio in dB for images in [0, 1]. Identical images give +inf.
pub fn psnr(rendered: &[f32], target: &[f32]) -> f64 {
    assert_eq!(rendered.len(), target.len(), "psnr: image sizes differ");
    if rendered.is_empty() {
        return f64::NAN;
    }
    let sum_sq: f64 = rendered
        .iter()
        .zip(target)
        .map(|(&a, &b)| {
            // Renders can exceed 1 (unclamped SH colour); PSNR is measured on the displayable range.
            let d = a.clamp(0.0, 1.0) as f64 - b as f64;
            d * d
        })
        .sum();
    let mse = sum_sq / rendered.len() as f64;
    -10.0 * mse.log10()
}

/// `psnr` over the pixels where `used` (one value per pixel) is non-zero: ignore masks keep
/// pedestrians and cars out of the score. NaN when no pixel is used.
pub fn psnr_masked(rendered: &[f32], target: &[f32], used: &[u8]) -> f64 {
    assert_eq!(rendered.len(), target.len(), "psnr: image sizes differ");
    assert_eq!(used.len() * 3, rendered.len(), "psnr: mask size");
    let (mut sum_sq, mut n) = (0.0f64, 0usize);
    for (p, &u) in used.iter().enumerate() {
        if u == 0 {
            continue;
        }
        for c in 0..3 {
            let d = rendered[p * 3 + c].clamp(0.0, 1.0) as f64 - target[p * 3 + c] as f64;
            sum_sq += d * d;
        }
        n += 3;
    }
    if n == 0 {
        return f64::NAN;
    }
    -10.0 * (sum_sq / n as f64).log10()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_of_uniform_error_is_analytic() {
        let a = vec![0.5f32; 30];
        let b = vec![0.6f32; 30];
        // mse = 0.01 -> 20 dB
        assert!((psnr(&a, &b) - 20.0).abs() < 1e-4);
        assert!(psnr(&a, &a).is_infinite());
    }

    #[test]
    fn masked_psnr_scores_only_the_used_pixels() {
        let a = vec![0.5f32; 30];
        let mut b = vec![0.6f32; 30];
        assert!((psnr_masked(&a, &b, &[1; 10]) - psnr(&a, &b)).abs() < 1e-9);
        // A wild pixel, ignored: the score is the other nine's.
        b[0..3].copy_from_slice(&[1.0, 0.0, 1.0]);
        let mut used = [1u8; 10];
        used[0] = 0;
        assert!((psnr_masked(&a, &b, &used) - 20.0).abs() < 1e-4);
        assert!(psnr_masked(&a, &b, &[0; 10]).is_nan());
    }
}
