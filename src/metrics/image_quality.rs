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
}
