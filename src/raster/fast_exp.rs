//! A branch-free `2^x` for the blending loops: the same bits on every lane width, so the forward
//! and backward (and SSE and AVX builds) make identical skip/stop decisions, and it vectorises.
//! Only for the Gaussian falloff, whose exponent the caller pre-scales by log2(e) (folded into
//! the conic once per row segment): that saves the range reduction's multiplies on every pixel.

/// `log2(e)`: `exp(x) = 2^(x · LOG2_E)`.
pub(crate) const LOG2_E: f32 = std::f32::consts::LOG2_E;

/// `2^x` with ~1 ulp error for `x` in `[-126, 127]`; clamps outside (so -inf gives 2^-126 and
/// NaN gives the clamp value: callers never pass NaN, culling removes it earlier).
#[inline(always)]
pub(crate) fn fast_exp2(x: f32) -> f32 {
    // Cephes `exp2f`: x = n + r with |r| <= 1/2, 2^r = 1 + r P(r), P of degree 5.
    // 1.5 * 2^23: adding it rounds to the nearest integer and leaves it in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    let x = if x < -126.0 { -126.0 } else { x };
    let x = if x > 127.0 { 127.0 } else { x };
    let shifted = x + ROUND;
    let n = shifted - ROUND;
    let n_int = (shifted.to_bits() as i32).wrapping_sub(ROUND.to_bits() as i32);
    let r = x - n;
    // Estrin's scheme instead of Horner's: a dependency depth of 3 multiply-adds instead of 5
    // (the blend loop waits on this chain).
    let r2 = r * r;
    let p01 = 6.931_472e-1 + 2.402_264_8e-1 * r;
    let p23 = 5.550_332_5e-2 + 9.618_437e-3 * r;
    let p45 = 1.339_887_4e-3 + 1.535_336_2e-4 * r;
    let p = p01 + r2 * (p23 + r2 * p45);
    let y = 1.0 + r * p;
    let scale = f32::from_bits(((n_int + 127) as u32) << 23);
    y * scale
}

#[cfg(test)]
mod tests {
    use super::{LOG2_E, fast_exp2};

    #[test]
    fn fast_exp2_is_within_two_ulp_of_std_over_the_falloff_range() {
        let mut worst = 0.0f64;
        let mut x = -125.0f32;
        while x <= 10.0 {
            let got = fast_exp2(x) as f64;
            let want = (x as f64).exp2();
            worst = worst.max(((got - want) / want).abs());
            x += 0.001_37;
        }
        // f32 epsilon is 1.19e-7: two ulp.
        assert!(worst < 2.4e-7, "worst relative error {worst}");
    }

    #[test]
    fn a_prescaled_exponent_gives_exp_within_a_few_ulp() {
        // The falloff computes exp(-sigma) as 2^(-sigma · log2 e), rounding the scaled
        // exponent once more: over the powers that can still blend (sigma <= ln 255 + ...).
        let mut worst = 0.0f64;
        let mut sigma = 0.0f32;
        while sigma <= 12.0 {
            let got = fast_exp2(-(sigma * LOG2_E)) as f64;
            let want = (-(sigma as f64)).exp();
            worst = worst.max(((got - want) / want).abs());
            sigma += 0.000_71;
        }
        assert!(worst < 1e-6, "worst relative error {worst}");
    }

    #[test]
    fn fast_exp2_saturates_instead_of_producing_nan_or_inf() {
        assert!(fast_exp2(-1e30) > 0.0 && fast_exp2(-1e30) < 1e-37);
        assert!(fast_exp2(f32::NEG_INFINITY) < 1e-37);
        assert!(fast_exp2(1e30).is_finite());
    }
}
