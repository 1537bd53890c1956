//! Each Gaussian's importance: its blending weight `Σ_views Σ_pixels α·T`, how much of the
//! training images it draws (Mini-Splatting's and LightGaussian's "global significance"), and
//! pruning a model to its `keep` most important Gaussians (`prune_to`).
//!
//! No renderer of its own: the sums come from `raster::weight_lift::WeightLift`, the same
//! exact-backward accumulation that lifts damage masks to Gaussians, with a weight of 1 on every
//! pixel the view trains (its loss region when it has one).

use crate::raster::RenderSettings;
use crate::raster::weight_lift::WeightLift;
use crate::splats::Splats;
use crate::train::spec::TrainView;

/// Importance of every Gaussian of `splats` over `views`: `Σ_v Σ_p α_gp T_gp` over each view's
/// loss region (all pixels when it has none). A Gaussian no view sees scores 0.
pub fn importance(splats: &Splats, views: &[TrainView], settings: &RenderSettings) -> Vec<f32> {
    let mut total = vec![0.0f32; splats.len()];
    if splats.is_empty() {
        return total;
    }
    let mut lift = WeightLift::new(splats, 1, *settings);
    for view in views {
        let region = view.region.as_ref();
        let weights = lift.view(&view.camera, |p, _| match region {
            Some(mask) if mask.data[p] == 0 => 0.0,
            _ => 1.0,
        });
        for (sum, &w) in total.iter_mut().zip(weights) {
            *sum += w;
        }
    }
    total
}

/// Keeps the `keep` most important Gaussians of `splats` (frozen ones are always kept and count
/// toward `keep`) and returns the keep mask it applied, so that optimiser and density state can
/// be pruned in step. Ties go to the lower index; a NaN importance ranks last.
pub fn prune_to(splats: &mut Splats, importance: &[f32], keep: usize) -> Vec<bool> {
    let mask = keep_mask(splats, importance, keep);
    splats.retain(&mask);
    mask
}

/// The mask `prune_to` applies, without applying it.
pub fn keep_mask(splats: &Splats, importance: &[f32], keep: usize) -> Vec<bool> {
    assert_eq!(
        importance.len(),
        splats.len(),
        "one importance per Gaussian"
    );
    let n = splats.len();
    let mut mask = vec![false; n];
    let mut left = keep;
    for (g, m) in mask.iter_mut().enumerate() {
        if splats.meta.frozen[g] {
            *m = true;
            left = left.saturating_sub(1);
        }
    }
    // `!(x >= 0)` sends NaN (and impossible negatives) to the bottom of the ranking.
    let rank = |g: usize| {
        let v = importance[g];
        if !(v >= 0.0) { f32::NEG_INFINITY } else { v }
    };
    let mut order: Vec<usize> = (0..n).filter(|&g| !splats.meta.frozen[g]).collect();
    order.sort_by(|&a, &b| rank(b).total_cmp(&rank(a)).then(a.cmp(&b)));
    for &g in order.iter().take(left) {
        mask[g] = true;
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Camera, Intrinsics, RgbImage};
    use glam::{Quat, Vec3};

    fn view() -> TrainView {
        let k = Intrinsics {
            width: 32,
            height: 32,
            fx: 32.0,
            fy: 32.0,
            cx: 16.0,
            cy: 16.0,
        };
        TrainView {
            name: "front".into(),
            camera: Camera::new(k, Quat::IDENTITY, Vec3::ZERO),
            image: RgbImage {
                width: 32,
                height: 32,
                data: vec![0.0; 32 * 32 * 3],
            },
            labels: Vec::new(),
            region: None,
            light: None,
        }
    }

    /// On the optical axis a wide, nearly opaque Gaussian with a small one right behind it, and a
    /// faint small one off to the side, nearer the camera.
    fn stack() -> Splats {
        let mut splats = Splats::empty(0, 0);
        let grey = [0.5, 0.5, 0.5];
        let small = Vec3::splat(0.1f32.ln());
        // Opacity logit 6 → α 0.9975; 1 m wide at 4 m is σ = 8 px, so within the small one's
        // half pixel of the axis the front one still has α ≈ 0.995: T ≤ 0.005 behind it.
        splats.push(
            Vec3::new(0.0, 0.0, 4.0),
            Vec3::ZERO,
            Quat::IDENTITY,
            6.0,
            &grey,
            &[],
            0,
            0,
        );
        splats.push(
            Vec3::new(0.0, 0.0, 6.0),
            small,
            Quat::IDENTITY,
            6.0,
            &grey,
            &[],
            1,
            0,
        );
        splats.push(
            Vec3::new(1.2, 0.0, 3.5),
            small,
            Quat::IDENTITY,
            -2.0,
            &grey,
            &[],
            2,
            0,
        );
        splats
    }

    #[test]
    fn hidden_gaussian_ranks_below_the_one_in_front() {
        let splats = stack();
        let score = importance(&splats, &[view()], &RenderSettings::default());
        assert!(
            score[0] > 10.0,
            "the front Gaussian covers many pixels: {score:?}"
        );
        // The one behind is wholly covered: only the half percent that leaks past the front
        // one's α reaches it.
        assert!(score[1] < 0.01 * score[0], "{score:?}");
        assert!(
            score[2] > score[1],
            "a faint visible Gaussian beats a hidden one: {score:?}"
        );
    }

    #[test]
    fn prune_to_keeps_exactly_the_most_important() {
        let mut splats = stack();
        let score = importance(&splats, &[view()], &RenderSettings::default());
        let mask = prune_to(&mut splats, &score, 2);
        assert_eq!(mask, vec![true, false, true]);
        assert_eq!(splats.len(), 2);
        assert_eq!(splats.meta.ids, vec![0, 2]);
        // Asking for more than there are keeps them all; for none keeps none.
        let all = stack();
        assert_eq!(keep_mask(&all, &score, 10), vec![true; 3]);
        assert_eq!(keep_mask(&all, &score, 0), vec![false; 3]);
    }

    #[test]
    fn frozen_gaussians_are_kept_and_nan_ranks_last() {
        let mut splats = stack();
        splats.meta.frozen[1] = true;
        let score = [f32::NAN, 0.0, 5.0];
        assert_eq!(keep_mask(&splats, &score, 2), vec![false, true, true]);
        splats.meta.frozen[1] = false;
        assert_eq!(keep_mask(&splats, &score, 2), vec![false, true, true]);
    }
}
