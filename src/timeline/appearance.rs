//! Appearance between surveys: a later survey is lit differently (sun, sky, exposure, white
//! balance), and an update must not repaint the twin with the new light. Per image a gain and an
//! offset per colour channel, `photo_c ≈ g_c · twin_c + o_c` (exposure and white balance, as
//! exposure compensation in 3DGS variants models them), is fitted in closed form (least
//! squares, pulled towards the identity) over the pixels where nothing changed, and the update
//! trains on the photos mapped back into the twin's look (`ColourTransform::undo`), so the
//! Gaussians keep their colours.
//!
//! Per channel, not a full 3×3 matrix: on a facade the three channels move together, so the
//! cross terms of a full matrix are nearly undetermined. On the demo building's survey 2 a full
//! fit came out as `[[1.36, -1.15, 0.59], …]` where the light was gains of about 0.87, 0.82 and
//! 0.72. After an update through it survey 1's held-out views lost 2.5 dB outside the damage,
//! against 1.9 dB with the per-channel fit: most of that loss has another cause
//! (docs/TIMELINE.md).

use crate::scene::Mask;
#[cfg(test)]
use crate::scene::RgbImage;
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

/// The pixels a fit may use: outside `masks` (damage, old or new), each grown by `margin`
/// pixels so blurred edges stay out too.
pub fn unchanged_pixels(masks: &[&Mask], width: u32, height: u32, margin: u32) -> Vec<bool> {
    let mut keep = vec![true; (width * height) as usize];
    let m = margin as i64;
    for mask in masks {
        for y in 0..height as i64 {
            for x in 0..width as i64 {
                if mask.data[(y * width as i64 + x) as usize] == 0 {
                    continue;
                }
                for yy in (y - m).max(0)..=(y + m).min(height as i64 - 1) {
                    let row = (yy * width as i64) as usize;
                    for xx in (x - m).max(0)..=(x + m).min(width as i64 - 1) {
                        keep[row + xx as usize] = false;
                    }
                }
            }
        }
    }
    keep
}

#[cfg(test)]
mod tests {
    use super::*;

    fn textured(width: u32, height: u32, seed: u64) -> RgbImage {
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
    fn changed_pixels_do_not_bend_the_fit() {
        let twin = textured(80, 60, 2);
        let mut photo = twin.clone();
        // New damage: a bright block the twin does not have, masked out of the fit.
        let mut damage = Mask::empty(80, 60);
        for y in 20..40 {
            for x in 20..50 {
                let p = (y * 80 + x) as usize;
                photo.data[p * 3..p * 3 + 3].copy_from_slice(&[1.0, 0.0, 0.0]);
                damage.data[p] = 1;
            }
        }
        let keep = unchanged_pixels(&[&damage], 80, 60, 2);
        let fitted = fit_transform(&twin.data, &photo.data, &|p| keep[p]);
        let identity = ColourTransform::IDENTITY;
        for c in 0..3 {
            for k in 0..3 {
                assert!((fitted.matrix[c][k] - identity.matrix[c][k]).abs() < 0.01);
            }
        }
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
