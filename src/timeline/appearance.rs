//! Appearance between surveys: a later survey is lit differently (sun, sky, exposure, white
//! balance), and an update must not repaint the twin with the new light. Per image an affine
//! colour transform `photo ≈ M · twin + o` is fitted in closed form (least squares, pulled
//! towards the identity) over the pixels where nothing changed, and the update trains on the
//! photos mapped back into the twin's look (`ColourTransform::undo`), so the Gaussians keep
//! their colours.

use crate::scene::Mask;
#[cfg(test)]
use crate::scene::RgbImage;
use crate::scene::project::ColourTransform;

/// Strength of the pull towards the identity (a ridge on M − I and o, in pixels × colour²): a
/// textured view's colours vary by ~0.04 (variance) per pixel, so this is worth ~125 pixels —
/// enough to keep a fit on a nearly uniform image from running away, nothing against the
/// ~500k pixels of a 960×540 view.
const PRIOR_STRENGTH: f64 = 5.0;

/// Fits `photo ≈ M · render + o` over the pixels where `use_pixel` (RGB interleaved, [0, 1]).
/// Indexed loops: the normal equations are written in matrix indices.
#[allow(clippy::needless_range_loop)]
pub fn fit_transform(
    render: &[f32],
    photo: &[f32],
    use_pixel: &dyn Fn(usize) -> bool,
) -> ColourTransform {
    // Normal equations of [r g b 1] against each photo channel, shared design matrix.
    let mut ata = [[0.0f64; 4]; 4];
    let mut atb = [[0.0f64; 4]; 3];
    for (p, (x, y)) in render
        .chunks_exact(3)
        .zip(photo.chunks_exact(3))
        .enumerate()
    {
        if !use_pixel(p) || !x.iter().chain(y).all(|v| v.is_finite()) {
            continue;
        }
        let a = [f64::from(x[0]), f64::from(x[1]), f64::from(x[2]), 1.0];
        for i in 0..4 {
            for j in 0..4 {
                ata[i][j] += a[i] * a[j];
            }
            for c in 0..3 {
                atb[c][i] += a[i] * f64::from(y[c]);
            }
        }
    }
    // The ridge towards M = I, o = 0, so an underdetermined fit falls back to "no change".
    for i in 0..3 {
        ata[i][i] += PRIOR_STRENGTH;
        atb[i][i] += PRIOR_STRENGTH;
    }
    ata[3][3] += PRIOR_STRENGTH;
    let mut out = ColourTransform::IDENTITY;
    for c in 0..3 {
        if let Some(x) = solve4(ata, atb[c]) {
            for k in 0..3 {
                out.matrix[c][k] = x[k] as f32;
            }
            out.offset[c] = x[3] as f32;
        }
    }
    out
}

/// Solves a 4×4 linear system by Gaussian elimination with partial pivoting.
#[allow(clippy::needless_range_loop)]
fn solve4(mut a: [[f64; 4]; 4], mut b: [f64; 4]) -> Option<[f64; 4]> {
    for col in 0..4 {
        let pivot = (col..4).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if !(a[pivot][col].abs() > 1e-12) {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in col + 1..4 {
            let f = a[row][col] / a[col][col];
            for k in col..4 {
                a[row][k] -= f * a[col][k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; 4];
    for row in (0..4).rev() {
        let mut v = b[row];
        for k in row + 1..4 {
            v -= a[row][k] * x[k];
        }
        x[row] = v / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
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
        // Survey 2's light: darker, warmer, a little cross-talk and a lift.
        let light = ColourTransform {
            matrix: [[0.95, 0.05, 0.0], [0.02, 0.82, 0.01], [0.0, 0.03, 0.7]],
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
}
