//! Seeded hashing, value noise, fbm and box-filtered stripe patterns for procedural textures.
//! Pure functions of their inputs (no global state), so every pixel depends only on its
//! coordinates and the seed; must not allocate or touch randomness sources.

/// lowbias32 integer hash (Chris Wellons): cheap and well mixed.
#[inline]
pub fn hash_u32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// Hash of a seed and two lattice coordinates.
#[inline]
pub fn hash2(seed: u32, a: i32, b: i32) -> u32 {
    hash_u32(
        seed ^ hash_u32((a as u32).wrapping_mul(0x9E37_79B1) ^ hash_u32(b as u32 ^ 0x85eb_ca6b)),
    )
}

/// Hash of a seed and three integers.
#[inline]
pub fn hash3(seed: u32, a: u32, b: u32, c: u32) -> u32 {
    hash_u32(hash2(seed, a as i32, b as i32) ^ c.wrapping_mul(0x27d4_eb2d))
}

/// A hash mapped to `[0, 1)`.
#[inline]
pub fn unit(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// Folds a 64-bit user seed into the 32-bit seeds the textures use.
pub fn seed32(seed: u64, stream: u32) -> u32 {
    hash_u32(
        (seed as u32) ^ hash_u32((seed >> 32) as u32 ^ hash_u32(stream.wrapping_add(0x1234_5678))),
    )
}

/// 2D value noise in `[0, 1]`, smooth (quintic fade) between integer lattice points.
#[inline]
pub fn value_noise(seed: u32, x: f32, y: f32) -> f32 {
    let xf = x.floor();
    let yf = y.floor();
    let (xi, yi) = (xf as i32, yf as i32);
    let (tx, ty) = (fade(x - xf), fade(y - yf));
    let a = unit(hash2(seed, xi, yi));
    let b = unit(hash2(seed, xi + 1, yi));
    let c = unit(hash2(seed, xi, yi + 1));
    let d = unit(hash2(seed, xi + 1, yi + 1));
    let top = a + (b - a) * tx;
    let bottom = c + (d - c) * tx;
    top + (bottom - top) * ty
}

#[inline]
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// Fractal sum of value noise in `[0, 1]`. Octaves whose lattice cell is smaller than
/// `footprint` (in the same units as `x`, `y`) are replaced by their mean, so distant surfaces
/// do not shimmer.
pub fn fbm(seed: u32, x: f32, y: f32, octaves: u32, footprint: f32) -> f32 {
    let mut sum = 0.0;
    let mut amp = 0.5;
    let mut norm = 0.0;
    let mut freq = 1.0;
    for k in 0..octaves {
        let cell = 1.0 / freq;
        // Fade an octave out as its cell shrinks from 4 to 1 pixel footprints.
        let keep = ((cell / footprint.max(1e-6) - 1.0) / 3.0).clamp(0.0, 1.0);
        let n = if keep > 0.0 {
            let s = hash_u32(seed.wrapping_add(k.wrapping_mul(0x6d2b_79f5)));
            // Per-octave offsets avoid lattice-aligned artefacts at the origin.
            let ox = unit(s) * 97.0;
            let oy = unit(hash_u32(s)) * 97.0;
            value_noise(s, x * freq + ox, y * freq + oy)
        } else {
            0.5
        };
        sum += amp * (0.5 + (n - 0.5) * keep);
        norm += amp;
        amp *= 0.5;
        freq *= 2.03;
    }
    sum / norm
}

/// Integral from 0 to `x` of a pulse train that is 1 on `[n p, n p + w)`.
#[inline]
fn pulse_integral(x: f32, period: f32, width: f32) -> f32 {
    let n = (x / period).floor();
    n * width + (x - n * period).min(width)
}

/// Fraction of a box filter of width `filter` centred on `x` covered by stripes of `width`
/// centred on multiples of `period` (mortar joints, tile gaps). Tends to `width / period` when the
/// filter spans many periods, which is what keeps brick courses from aliasing.
#[inline]
pub fn filtered_stripes(x: f32, period: f32, width: f32, filter: f32) -> f32 {
    let x = x + 0.5 * width;
    if !(filter > 1e-5) {
        let r = x - (x / period).floor() * period;
        return if r < width { 1.0 } else { 0.0 };
    }
    let h = 0.5 * filter;
    ((pulse_integral(x + h, period, width) - pulse_integral(x - h, period, width)) / filter)
        .clamp(0.0, 1.0)
}

/// Coverage of the band `|d| < half_width` by a box filter of width `filter` centred at
/// distance `d` (crack and rebar edges).
#[inline]
pub fn band_coverage(d: f32, half_width: f32, filter: f32) -> f32 {
    let d = d.abs();
    let h = 0.5 * filter.max(1e-6);
    let overlap = (d + h).min(half_width) - (d - h).max(-half_width);
    (overlap / filter.max(1e-6)).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_noise_is_continuous_and_in_range() {
        for i in 0..1000 {
            let x = i as f32 * 0.0137 - 3.0;
            let a = value_noise(7, x, 0.3);
            let b = value_noise(7, x + 1e-3, 0.3);
            assert!((0.0..=1.0).contains(&a));
            assert!((a - b).abs() < 0.01, "jump at {x}");
        }
    }

    #[test]
    fn filtered_stripes_average_to_duty_cycle() {
        // A filter spanning 10 periods sees the duty cycle width / period.
        let c = filtered_stripes(0.37, 0.1, 0.01, 1.0);
        assert!((c - 0.1).abs() < 1e-3, "{c}");
        assert_eq!(filtered_stripes(0.0, 0.1, 0.01, 0.0), 1.0);
        assert_eq!(filtered_stripes(0.05, 0.1, 0.01, 0.0), 0.0);
    }

    #[test]
    fn band_coverage_is_full_inside_and_zero_far_away() {
        assert_eq!(band_coverage(0.0, 1.0, 0.5), 1.0);
        assert_eq!(band_coverage(3.0, 1.0, 0.5), 0.0);
        assert!((band_coverage(0.0, 0.1, 1.0) - 0.2).abs() < 1e-6);
    }
}
