//! `exp` and `ln` written as straight-line arithmetic, for the projection's 8-Gaussian lane
//! loops: a libm call in a loop body stops LLVM from vectorising it, these do not. Same bits on
//! every lane width (no FMA, fixed operation order), so SSE2/AVX2/AVX-512 builds agree. They
//! evaluate in double and round once, as glibc's `expf`/`logf` do, to give the same bits.

/// 1.5 · 2^52: adding it rounds a double of magnitude < 2^51 to the nearest integer and leaves
/// that integer in the low mantissa bits.
const ROUND: f64 = 6_755_399_441_055_744.0;

/// `e^x`, rounded to f32 from a double evaluation, so it agrees with `f32::exp` (glibc's is
/// correctly rounded, also through a double) in practically every bit. The projection's
/// finite-difference gradient tests sit on culling and radius thresholds, where a one-ulp
/// difference in a scale can move a crossing into the difference window. Handles the whole
/// range: `0` for `-inf` and underflow, `+inf` for `+inf` and overflow, NaN for NaN.
#[inline(always)]
pub(crate) fn exp_lane(x: f32) -> f32 {
    // Past these ends f32's e^x is 0 or +inf; clamping keeps the reduction finite. Compares,
    // not `max`/`min`, so that NaN passes through.
    let xc = if x < -104.0 { -104.0 } else { x };
    let xc = if xc > 89.0 { 89.0 } else { xc };
    let x64 = xc as f64;
    // x = n ln2 + r, |r| <= ln2 / 2; n ln2 in double is exact enough for |n| <= 150.
    let shifted = x64 * std::f64::consts::LOG2_E + ROUND;
    let n = shifted - ROUND;
    let n_int = (shifted.to_bits() as i64).wrapping_sub(ROUND.to_bits() as i64);
    let r = x64 - n * std::f64::consts::LN_2;
    // Taylor to degree 8: relative error < 2e-10 on |r| <= 0.35, far inside half an f32 ulp.
    let mut p = 1.0 / 40_320.0;
    for c in [
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    // n in [-151, 129]: 2^n is a normal double, and the single rounding to f32 below gives
    // subnormals, 0 and inf where e^x has them.
    let scale = f64::from_bits((n_int.wrapping_add(1023) as u64) << 52);
    (p * scale) as f32
}

/// `1 / (1 + e^-x)`, the opacity and label activation, from [`exp_lane`].
#[inline(always)]
pub(crate) fn sigmoid_lane(x: f32) -> f32 {
    1.0 / (1.0 + exp_lane(-x))
}

/// Natural log of a positive normal `x`, rounded to f32 from a double evaluation (as
/// [`exp_lane`], to agree with `f32::ln`); `+inf` gives `+inf`, NaN and negative `x` give NaN.
/// (Subnormals are not handled: the callers' arguments are at least 1.)
#[inline(always)]
pub(crate) fn ln_lane(x: f32) -> f32 {
    // x = m · 2^e with m in [sqrt(1/2), sqrt(2)), ln x = e ln2 + ln m.
    const SQRT_HALF: f32 = std::f32::consts::FRAC_1_SQRT_2;
    let bits = x.to_bits() as i32;
    let e = ((bits >> 23) & 0xff) - 126;
    let m = f32::from_bits(((bits & 0x007f_ffff) | 0x3f00_0000) as u32);
    let low = m < SQRT_HALF;
    let e = (if low { e - 1 } else { e }) as f64;
    let m = (if low { m + m } else { m }) as f64;
    // ln m = 2 atanh(s), s = (m - 1) / (m + 1), |s| <= 0.172: odd series to s^15, relative
    // error < 1e-13.
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let mut p = 1.0 / 15.0;
    for c in [
        1.0 / 13.0,
        1.0 / 11.0,
        1.0 / 9.0,
        1.0 / 7.0,
        1.0 / 5.0,
        1.0 / 3.0,
        1.0,
    ] {
        p = p * s2 + c;
    }
    let ln = (e * std::f64::consts::LN_2 + 2.0 * s * p) as f32;
    let ln = if x == f32::INFINITY { x } else { ln };
    if x >= 0.0 { ln } else { f32::NAN }
}

#[cfg(test)]
mod tests {
    use super::{exp_lane, ln_lane, sigmoid_lane};

    fn rel(got: f32, want: f32) -> f64 {
        ((got as f64 - want as f64) / want as f64).abs()
    }

    #[test]
    fn exp_lane_is_within_two_ulp_of_std_over_the_normal_range() {
        let mut worst = 0.0f64;
        let mut x = -87.0f32;
        while x <= 88.5 {
            worst = worst.max(rel(exp_lane(x), x.exp()));
            x += 0.000_913;
        }
        // f32 epsilon is 1.19e-7: within half an ulp of the correctly rounded value, so
        // within one ulp of std's.
        assert!(worst < 1.2e-7, "worst relative error {worst}");
    }

    #[test]
    fn exp_lane_ends_match_std() {
        assert_eq!(exp_lane(f32::NEG_INFINITY), 0.0);
        assert_eq!(exp_lane(-1e30), 0.0);
        assert_eq!(exp_lane(-104.5), 0.0);
        assert_eq!(exp_lane(f32::INFINITY), f32::INFINITY);
        assert_eq!(exp_lane(89.0), f32::INFINITY);
        assert_eq!(exp_lane(1e30), f32::INFINITY);
        assert!(exp_lane(f32::NAN).is_nan());
        assert_eq!(exp_lane(0.0), 1.0);
        // Subnormal results: one rounding, as std.
        for x in [-88.0f32, -95.0, -100.0, -103.0] {
            let (got, want) = (exp_lane(x), x.exp());
            assert!(rel(got, want) < 1e-3, "{x}: {got} vs {want}");
        }
    }

    #[test]
    fn exp_lane_gives_the_bits_of_std_almost_everywhere() {
        let (mut same, mut total) = (0, 0);
        let mut x = -30.0f32;
        while x <= 30.0 {
            same += (exp_lane(x) == x.exp()) as usize;
            total += 1;
            x += 0.000_731;
        }
        // Both are (nearly) correctly rounded: a handful of near-ties may differ.
        assert!(same * 1000 >= total * 999, "{same} of {total} agree");
    }

    #[test]
    fn sigmoid_lane_saturates_like_std() {
        assert_eq!(sigmoid_lane(f32::INFINITY), 1.0);
        assert_eq!(sigmoid_lane(f32::NEG_INFINITY), 0.0);
        assert!(sigmoid_lane(f32::NAN).is_nan());
        for x in [-20.0f32, -3.0, 0.0, 0.7, 12.0] {
            let want = 1.0 / (1.0 + (-x).exp());
            assert!(rel(sigmoid_lane(x), want) < 2.4e-7);
        }
    }

    #[test]
    fn ln_lane_is_within_two_ulp_of_std() {
        let mut worst = 0.0f64;
        let mut x = 1e-30f32;
        while x < 1e30 {
            let want = x.ln();
            // Relative error is meaningless near ln 1 = 0: compare absolutely there.
            let err = if want.abs() < 1.0 {
                (ln_lane(x) - want).abs() as f64
            } else {
                rel(ln_lane(x), want)
            };
            worst = worst.max(err);
            x *= 1.000_37;
        }
        assert!(worst < 1.2e-7, "worst error {worst}");
        assert_eq!(ln_lane(1.0), 0.0);
        assert_eq!(ln_lane(f32::INFINITY), f32::INFINITY);
        assert!(ln_lane(f32::NAN).is_nan());
        assert!(ln_lane(-1.0).is_nan());
    }
}
