//! A branch-free `2^x` for the blending loops: it vectorises, and gives the same bits on every
//! lane width of one build (the AVX builds fuse its multiply-adds, the baseline one does not;
//! the backward replays the forward's stored values, so it never needs to agree with another
//! build). Only for the Gaussian falloff, whose exponent the caller pre-scales by log2(e)
//! (folded into the conic once per intersection): that saves the range reduction's multiplies
//! on every pixel.

use crate::simd::Arith;

/// `log2(e)`: `exp(x) = 2^(x · LOG2_E)`.
pub(crate) const LOG2_E: f32 = std::f32::consts::LOG2_E;

/// `2^x = mantissa · scale` with ~1 ulp error for `x` in `[-126, 127]`, `scale` a power of two;
/// clamps outside (so -inf gives 2^-126 and NaN gives the clamp value: callers never pass NaN,
/// culling removes it earlier). Split in two because a caller that also
/// wants `k · 2^x` multiplies the mantissa by `k · scale`, computed beside the polynomial rather
/// than after it (the same bits wherever `k · scale` is a normal number: both products are then
/// the exact product rounded once).
#[inline(always)]
pub(crate) fn exp2_parts<F: Arith>(x: f32) -> (f32, f32) {
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
    let p01 = F::mul_add(2.402_264_8e-1, r, 6.931_472e-1);
    let p23 = F::mul_add(9.618_437e-3, r, 5.550_332_5e-2);
    let p45 = F::mul_add(1.535_336_2e-4, r, 1.339_887_4e-3);
    let p = F::mul_add(r2, F::mul_add(r2, p45, p23), p01);
    let mantissa = F::mul_add(r, p, 1.0);
    let scale = f32::from_bits(((n_int + 127) as u32) << 23);
    (mantissa, scale)
}

#[cfg(test)]
mod tests {
    use super::{LOG2_E, exp2_parts};
    use crate::simd::{Arith, Fused, Separate};

    fn fast_exp2<F: Arith>(x: f32) -> f32 {
        let (mantissa, scale) = exp2_parts::<F>(x);
        mantissa * scale
    }

    fn worst_error_against_exp2<F: Arith>() -> f64 {
        let mut worst = 0.0f64;
        let mut x = -125.0f32;
        while x <= 10.0 {
            let got = fast_exp2::<F>(x) as f64;
            let want = (x as f64).exp2();
            worst = worst.max(((got - want) / want).abs());
            x += 0.001_37;
        }
        worst
    }

    #[test]
    fn fast_exp2_is_within_two_ulp_of_std_over_the_falloff_range() {
        // f32 epsilon is 1.19e-7: two ulp. Both builds: fused (AVX) and separate (baseline).
        for worst in [
            worst_error_against_exp2::<Fused>(),
            worst_error_against_exp2::<Separate>(),
        ] {
            assert!(worst < 2.4e-7, "worst relative error {worst}");
        }
    }

    fn worst_error_prescaled<F: Arith>() -> f64 {
        let mut worst = 0.0f64;
        let mut sigma = 0.0f32;
        while sigma <= 12.0 {
            let got = fast_exp2::<F>(-(sigma * LOG2_E)) as f64;
            let want = (-(sigma as f64)).exp();
            worst = worst.max(((got - want) / want).abs());
            sigma += 0.000_71;
        }
        worst
    }

    #[test]
    fn a_prescaled_exponent_gives_exp_within_a_few_ulp() {
        // The falloff computes exp(-sigma) as 2^(-sigma · log2 e), rounding the scaled
        // exponent once more: over the powers that can still blend (sigma <= ln 255 + ...).
        for worst in [
            worst_error_prescaled::<Fused>(),
            worst_error_prescaled::<Separate>(),
        ] {
            assert!(worst < 1e-6, "worst relative error {worst}");
        }
    }

    fn saturates<F: Arith>() {
        assert!(fast_exp2::<F>(-1e30) > 0.0 && fast_exp2::<F>(-1e30) < 1e-37);
        assert!(fast_exp2::<F>(f32::NEG_INFINITY) < 1e-37);
        assert!(fast_exp2::<F>(1e30).is_finite());
    }

    #[test]
    fn fast_exp2_saturates_instead_of_producing_nan_or_inf() {
        saturates::<Fused>();
        saturates::<Separate>();
    }
}
