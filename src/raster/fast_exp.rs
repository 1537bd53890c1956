//! A branch-free `exp` for the blending loops: the same bits on every lane width, so the forward
//! and backward (and SSE and AVX builds) make identical skip/stop decisions, and it vectorises.
//! Only for the Gaussian falloff; not a general-purpose libm replacement.

/// `exp(x)` with ~1 ulp error for `x` in `[-87, 88]`; clamps outside (so -inf gives ~1e-38 and
/// NaN gives the clamp value: callers never pass NaN, culling removes it earlier).
#[inline(always)]
pub(crate) fn fast_exp(x: f32) -> f32 {
    // Cephes `expf`: x = n ln2 + r with |r| <= ln2 / 2, exp(r) by a degree-6 polynomial.
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // 1.5 * 2^23: adding it rounds to the nearest integer and leaves it in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    let x = if x < -87.0 { -87.0 } else { x };
    let x = if x > 88.0 { 88.0 } else { x };
    let shifted = x * LOG2E + ROUND;
    let n = shifted - ROUND;
    let n_int = (shifted.to_bits() as i32).wrapping_sub(ROUND.to_bits() as i32);
    let r = x - n * LN2_HI - n * LN2_LO;
    let mut p = 1.987_569_1e-4f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 0.5;
    let y = p * r * r + r + 1.0;
    let scale = f32::from_bits(((n_int + 127) as u32) << 23);
    y * scale
}

#[cfg(test)]
mod tests {
    use super::fast_exp;

    #[test]
    fn fast_exp_is_within_two_ulp_of_std_over_the_falloff_range() {
        let mut worst = 0.0f64;
        let mut x = -87.0f32;
        while x <= 10.0 {
            let got = fast_exp(x) as f64;
            let want = (x as f64).exp();
            worst = worst.max(((got - want) / want).abs());
            x += 0.001_37;
        }
        // f32 epsilon is 1.19e-7: two ulp.
        assert!(worst < 2.4e-7, "worst relative error {worst}");
    }

    #[test]
    fn fast_exp_saturates_instead_of_producing_nan_or_inf() {
        assert!(fast_exp(-1e30) >= 0.0 && fast_exp(-1e30) < 1e-37);
        assert!(fast_exp(f32::NEG_INFINITY) < 1e-37);
        assert!(fast_exp(1e30).is_finite());
    }
}
