//! Mask corruption for robustness studies: which views get noisy masks, and irregular blobs
//! added to and cut out of their masks (like the published method's Figure 11). Works on mask
//! buffers only; the clean masks are kept elsewhere and must never be passed here.

use super::noise::value_noise;
use crate::scene::DamageClass;

/// Exactly `round(fraction · n)` views, chosen by the seed.
pub fn noisy_views(n: usize, fraction: f32, seed: u64) -> Vec<bool> {
    let count = ((fraction * n as f32).round() as usize).min(n);
    let mut order: Vec<usize> = (0..n).collect();
    fastrand::Rng::with_seed(seed ^ 0x0B10_B500).shuffle(&mut order);
    let mut noisy = vec![false; n];
    for &i in &order[..count] {
        noisy[i] = true;
    }
    noisy
}

/// Corrupts one view's mask of `class` the way `synth --mask-noise` does: two false and two
/// missed blobs for cracks, one or two of each for spalling, at most one added for rebar.
pub fn corrupt_class_mask(
    class: DamageClass,
    mask: &mut [u8],
    width: usize,
    height: usize,
    building: &[bool],
    rng: &mut fastrand::Rng,
) {
    let (adds, removes) = match class {
        DamageClass::Crack => (2, 2),
        DamageClass::Spalling => (1 + rng.usize(0..2), 1 + rng.usize(0..2)),
        DamageClass::Rebar => (rng.usize(0..2), 1),
    };
    corrupt_mask(mask, width, height, building, adds, removes, rng);
}

/// Adds and removes blobs in one binary (0/1) mask of `width × height`; `building` marks pixels
/// where added blobs may be centred (non-sky). Guarantees at least one pixel changes.
pub fn corrupt_mask(
    mask: &mut [u8],
    width: usize,
    height: usize,
    building: &[bool],
    adds: usize,
    removes: usize,
    rng: &mut fastrand::Rng,
) {
    let before: usize = mask.iter().map(|&v| v as usize).sum();
    let scale = width as f32 / 960.0;
    let on: Vec<usize> = (0..mask.len()).filter(|&i| mask[i] != 0).collect();
    let candidates: Vec<usize> = (0..building.len()).filter(|&i| building[i]).collect();
    for _ in 0..adds {
        // Half the false positives sit next to real damage, half anywhere on the structure.
        let pool = if !on.is_empty() && rng.bool() {
            &on
        } else {
            &candidates
        };
        let centre = if pool.is_empty() {
            rng.usize(0..mask.len())
        } else {
            pool[rng.usize(0..pool.len())]
        };
        let radius = (6.0 + 22.0 * rng.f32()) * scale.max(0.1);
        blob(mask, width, height, centre, radius.max(2.0), 1, rng.u32(..));
    }
    for _ in 0..removes {
        if on.is_empty() {
            break;
        }
        let centre = on[rng.usize(0..on.len())];
        let radius = (5.0 + 18.0 * rng.f32()) * scale.max(0.1);
        blob(mask, width, height, centre, radius.max(2.0), 0, rng.u32(..));
    }
    let after: usize = mask.iter().map(|&v| v as usize).sum();
    if after == before && adds + removes > 0 {
        // Equal counts almost surely mean nothing changed; flip one pixel to keep the promise.
        let i = rng.usize(0..mask.len());
        mask[i] ^= 1;
    }
}

/// Corrupts one binary (0/1) mask the way the published method's Figure 11 does, with an error
/// proportional to the view's own damage: irregular regions added and removed until about
/// `rate × damage area` pixels differ from the clean mask, half false (added, half of them next to
/// the damage, half anywhere on the structure) and half missed (cut out of the damage). A view
/// without damage is left clean. Returns the pixels changed.
pub fn corrupt_mask_by_area(
    mask: &mut [u8],
    width: usize,
    height: usize,
    building: &[bool],
    rate: f32,
    rng: &mut fastrand::Rng,
) -> usize {
    let on: Vec<usize> = (0..mask.len()).filter(|&i| mask[i] != 0).collect();
    let target = (rate * on.len() as f32).round() as usize;
    if target == 0 {
        return 0;
    }
    let clean = mask.to_vec();
    let changed = |mask: &[u8]| mask.iter().zip(&clean).filter(|(a, b)| a != b).count();
    let candidates: Vec<usize> = (0..building.len()).filter(|&i| building[i]).collect();
    let max_radius = 28.0 * (width as f32 / 960.0).max(0.1);
    // Each kind gets half the error; a blob is sized to what is left of its half, so small
    // errors come as small regions and large ones as a few larger regions.
    for (value, share) in [(0u8, target / 2), (1u8, target - target / 2)] {
        let goal = changed(mask) + share;
        for _ in 0..400 {
            let now = changed(mask);
            if now >= goal {
                break;
            }
            let left = (goal - now) as f32;
            let anywhere = value == 1 && !candidates.is_empty() && rng.bool();
            let centre = if anywhere {
                candidates[rng.usize(0..candidates.len())]
            } else {
                on[rng.usize(0..on.len())]
            };
            // Removing from a thin crack clears about a diameter's length of it per blob; adding
            // fills the blob's area.
            let radius = if value == 0 {
                (left / 2.0).clamp(1.5, max_radius)
            } else {
                (left / std::f32::consts::PI).sqrt().clamp(1.5, max_radius)
            };
            blob(mask, width, height, centre, radius, value, rng.u32(..));
        }
    }
    changed(mask)
}

/// Sets an irregular blob (radius modulated by angular noise) to `value`.
fn blob(
    mask: &mut [u8],
    width: usize,
    height: usize,
    centre: usize,
    radius: f32,
    value: u8,
    seed: u32,
) {
    let (cx, cy) = ((centre % width) as f32 + 0.5, (centre / width) as f32 + 0.5);
    let reach = radius * 1.5;
    let x0 = (cx - reach).floor().max(0.0) as usize;
    let y0 = (cy - reach).floor().max(0.0) as usize;
    let x1 = ((cx + reach).ceil() as usize).min(width);
    let y1 = ((cy + reach).ceil() as usize).min(height);
    for y in y0..y1 {
        for x in x0..x1 {
            let d = glam::Vec2::new(x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
            let len = d.length();
            let dir = if len > 1e-6 { d / len } else { glam::Vec2::X };
            let r = radius * (0.6 + 0.7 * value_noise(seed, 1.5 * dir.x + 9.0, 1.5 * dir.y + 9.0));
            if len < r {
                mask[y * width + x] = value;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn area_corruption_changes_about_the_rate_times_the_damage() {
        let (w, h) = (240, 135);
        let building = vec![true; w * h];
        for (rate, seed) in [(0.1f32, 1u64), (0.4, 2), (0.8, 3)] {
            let mut mask = vec![0u8; w * h];
            // A 3-pixel-wide crack-like band and a 30×20 patch: 930 + 600 pixels.
            for x in 20..330.min(w) {
                for y in 60..63 {
                    mask[y * w + x.min(w - 1)] = 1;
                }
            }
            for y in 10..30 {
                for x in 150..180 {
                    mask[y * w + x] = 1;
                }
            }
            let area = mask.iter().filter(|&&v| v != 0).count();
            let clean = mask.clone();
            let mut rng = fastrand::Rng::with_seed(seed);
            let changed = corrupt_mask_by_area(&mut mask, w, h, &building, rate, &mut rng);
            let expected = rate * area as f32;
            assert!(
                (changed as f32) >= expected && (changed as f32) < expected * 1.6 + 60.0,
                "rate {rate}: {changed} changed of {area}"
            );
            let added = mask.iter().zip(&clean).filter(|&(&m, &c)| m > c).count();
            let removed = mask.iter().zip(&clean).filter(|&(&m, &c)| m < c).count();
            assert!(added > 0 && removed > 0, "rate {rate}: +{added} -{removed}");
        }
        let mut empty = vec![0u8; w * h];
        let mut rng = fastrand::Rng::with_seed(4);
        assert_eq!(
            corrupt_mask_by_area(&mut empty, w, h, &building, 0.8, &mut rng),
            0
        );
    }

    #[test]
    fn noisy_views_picks_the_rounded_fraction() {
        let v = noisy_views(60, 0.25, 3);
        assert_eq!(v.iter().filter(|&&b| b).count(), 15);
        assert_eq!(noisy_views(10, 0.0, 3).iter().filter(|&&b| b).count(), 0);
    }

    #[test]
    fn corruption_changes_an_empty_mask() {
        let mut m = vec![0u8; 64 * 32];
        let building = vec![true; 64 * 32];
        let mut rng = fastrand::Rng::with_seed(1);
        corrupt_mask(&mut m, 64, 32, &building, 1, 1, &mut rng);
        assert!(m.iter().any(|&v| v != 0));
    }
}
