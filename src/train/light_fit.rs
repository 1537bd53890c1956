//! A photo's light fitted to a render in closed form: per colour channel a gain and an offset,
//! `photo_c ≈ g_c · render_c + o_c` (exposure and white balance, as exposure compensation in
//! 3DGS variants models them), by least squares pulled towards the identity. The timeline fits a
//! later survey's light with it (`timeline::appearance`), and evaluation fits a held-out photo's
//! on one half to score the other (`damage::assess`, the NeRF-W protocol); training learns the
//! same transform instead (`train::appearance`).

use crate::scene::project::ColourTransform;

/// Strength of the pull towards the identity (a ridge on g − 1 and o, in pixels × colour²): a
/// textured view's colours vary by ~0.04 (variance) per pixel, so this is worth ~125 pixels —
/// enough to keep a fit on a nearly uniform image from running away, nothing against the
/// ~500k pixels of a 960×540 view.
const PRIOR_STRENGTH: f64 = 5.0;

/// Fits `photo_c ≈ g_c · render_c + o_c` per channel over the pixels where `use_pixel` (RGB
/// interleaved, [0, 1]). The result's matrix is diagonal.
pub fn fit_transform(
    render: &[f32],
    photo: &[f32],
    use_pixel: &dyn Fn(usize) -> bool,
) -> ColourTransform {
    // Per channel the normal equations of [x 1] against y: sums of x², x, 1, x·y and y.
    let mut sums = [[0.0f64; 5]; 3];
    for (p, (x, y)) in render
        .chunks_exact(3)
        .zip(photo.chunks_exact(3))
        .enumerate()
    {
        if !use_pixel(p) || !x.iter().chain(y).all(|v| v.is_finite()) {
            continue;
        }
        for c in 0..3 {
            let (x, y) = (f64::from(x[c]), f64::from(y[c]));
            let s = &mut sums[c];
            s[0] += x * x;
            s[1] += x;
            s[2] += 1.0;
            s[3] += x * y;
            s[4] += y;
        }
    }
    let mut out = ColourTransform::IDENTITY;
    for (c, [xx, x, n, xy, y]) in sums.into_iter().enumerate() {
        // The ridge towards g = 1, o = 0, so an underdetermined fit falls back to "no change".
        let (a, b, d) = (xx + PRIOR_STRENGTH, x, n + PRIOR_STRENGTH);
        let (r0, r1) = (xy + PRIOR_STRENGTH, y);
        let det = a * d - b * b;
        if !(det.abs() > 1e-12) {
            continue;
        }
        let gain = (r0 * d - b * r1) / det;
        let offset = (a * r1 - b * r0) / det;
        if gain.is_finite() && offset.is_finite() {
            out.matrix[c][c] = gain as f32;
            out.offset[c] = offset as f32;
        }
    }
    out
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::scene::RgbImage;

    /// An image of random colours in [0.1, 0.8] (also the timeline's fits' test photo).
    pub(crate) fn textured(width: u32, height: u32, seed: u64) -> RgbImage {
        let mut rng = fastrand::Rng::with_seed(seed);
        RgbImage {
            width,
            height,
            data: (0..width * height * 3)
                .map(|_| 0.1 + 0.7 * rng.f32())
                .collect(),
        }
    }

    #[test]
    fn a_relit_view_is_matched_and_mapped_back_to_the_twin_look() {
        let twin = textured(80, 60, 1);
        // Survey 2's light: darker, warmer (per-channel gains) and a lift.
        let light = ColourTransform {
            matrix: [[0.95, 0.0, 0.0], [0.0, 0.82, 0.0], [0.0, 0.0, 0.7]],
            offset: [0.03, 0.01, -0.02],
        };
        let mut photo = twin.clone();
        light.apply(&mut photo);
        let fitted = fit_transform(&twin.data, &photo.data, &|_| true);
        for c in 0..3 {
            for k in 0..3 {
                // The ridge's pull over 4800 pixels: within 0.02.
                assert!(
                    (fitted.matrix[c][k] - light.matrix[c][k]).abs() < 0.02,
                    "{fitted:?}"
                );
            }
            assert!(
                (fitted.offset[c] - light.offset[c]).abs() < 0.02,
                "{fitted:?}"
            );
        }
        let mut back = photo.clone();
        fitted.undo(&mut back);
        let worst = back
            .data
            .iter()
            .zip(&twin.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        // Measured 0.004: the relit photo maps back onto the twin's colours.
        assert!(worst < 0.02, "{worst}");
    }

    #[test]
    fn grey_surfaces_give_a_stable_fit() {
        // A facade whose channels move together: nearly grey, so a full 3×3 fit is nearly
        // undetermined. The per-channel fit recovers the gains.
        let mut rng = fastrand::Rng::with_seed(3);
        let mut twin = RgbImage {
            width: 80,
            height: 60,
            data: Vec::with_capacity(80 * 60 * 3),
        };
        for _ in 0..80 * 60 {
            let grey = 0.2 + 0.6 * rng.f32();
            for tint in [1.0, 0.97, 0.94] {
                twin.data.push(grey * tint + 0.005 * (rng.f32() - 0.5));
            }
        }
        let light = ColourTransform {
            matrix: [[0.87, 0.0, 0.0], [0.0, 0.82, 0.0], [0.0, 0.0, 0.72]],
            offset: [0.0; 3],
        };
        let mut photo = twin.clone();
        light.apply(&mut photo);
        let fitted = fit_transform(&twin.data, &photo.data, &|_| true);
        for c in 0..3 {
            for k in 0..3 {
                let err = (fitted.matrix[c][k] - light.matrix[c][k]).abs();
                assert!(err < 0.02, "{fitted:?}");
            }
        }
    }
}
