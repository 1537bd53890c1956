//! How much of a point a camera sees through the twin: the transmittance of the Gaussians along
//! the ray between them, each evaluated at its peak along the ray (as ray-traced Gaussian
//! renderers do). Tells the side of a facade its photos were taken from: a photo from across the
//! building has the centre of the far facade in its image, but sees it through two walls.

use std::collections::BTreeSet;

use glam::{DMat3, DVec3};
use kiddo::{KdTree, SquaredEuclidean};

use crate::splats::Splats;
use crate::splats::model::sigmoid;

/// Most samples along one ray: 4096 at the metric step of 5 cm is a 200 m ray, longer than any
/// photo's distance to the structure it shows.
pub const MAX_RAY_SAMPLES: usize = 4096;

/// How a ray of `length` is sampled: the sample count, the step and the reach, the step and the
/// reach grown together when `step` would take more than `MAX_RAY_SAMPLES` samples.
fn ray_sampling(length: f64, step: f64, reach: f64) -> (usize, f64, f64) {
    let coarser = (length / step / MAX_RAY_SAMPLES as f64).max(1.0);
    let (step, reach) = (step * coarser, reach * coarser);
    ((length / step).ceil() as usize, step, reach)
}

pub struct Occlusion<'a> {
    splats: &'a Splats,
    tree: KdTree<f64, 3>,
}

impl<'a> Occlusion<'a> {
    pub fn new(splats: &'a Splats) -> Occlusion<'a> {
        let mut tree: KdTree<f64, 3> = KdTree::with_capacity(splats.len());
        for (g, m) in splats.means.iter().enumerate() {
            tree.add(&m.as_dvec3().to_array(), g as u64);
        }
        Occlusion { splats, tree }
    }

    /// Transmittance from `from` to within `stop` of `to` (the surface's own Gaussians at `to`
    /// are not in the way): the ray is sampled every `step`, and the Gaussians centred within
    /// `reach` of a sample are evaluated.
    pub fn transmittance(&self, from: DVec3, to: DVec3, stop: f64, step: f64, reach: f64) -> f64 {
        let length = from.distance(to) - stop;
        if !(length > 0.0) {
            return 1.0;
        }
        let direction = (to - from).normalize();
        let mut near = BTreeSet::new();
        // A scale typed in the wrong unit (1000 metres per unit for 1 mm) made the step a
        // millionth of the ray and one test took minutes: past `MAX_RAY_SAMPLES` the step and
        // the reach grow together, so the samples still cover the ray (reach ≥ step / 2 as set).
        let (samples, step, reach) = ray_sampling(length, step, reach);
        for k in 0..=samples {
            let p = from + direction * (k as f64 * step).min(length);
            for hit in self
                .tree
                .within_unsorted::<SquaredEuclidean>(&p.to_array(), reach * reach)
            {
                near.insert(hit.item as usize);
            }
        }
        let mut transmittance = 1.0;
        for g in near {
            let alpha = self.peak_alpha(g, from, direction, length);
            transmittance *= 1.0 - alpha;
        }
        transmittance
    }

    /// Opacity of Gaussian `g` at its peak along the ray, when the peak lies on the segment.
    fn peak_alpha(&self, g: usize, origin: DVec3, direction: DVec3, length: f64) -> f64 {
        let s = self.splats;
        let rotation = DMat3::from_quat(s.rotations[g].as_dquat().normalize());
        let inverse_variance = (-2.0 * s.log_scales[g].as_dvec3()).exp();
        // Σ⁻¹ = R diag(1/σ²) Rᵀ, applied as Rᵀ then the diagonal.
        let to_mean = rotation.transpose() * (s.means[g].as_dvec3() - origin);
        let d = rotation.transpose() * direction;
        let dd = (d * d * inverse_variance).element_sum();
        if !(dd > 0.0) {
            return 0.0;
        }
        let t = (d * to_mean * inverse_variance).element_sum() / dd;
        if !(t > 0.0 && t < length) {
            return 0.0;
        }
        let offset = to_mean - d * t;
        let power = -0.5 * (offset * offset * inverse_variance).element_sum();
        (f64::from(sigmoid(s.raw_opacities[g])) * power.exp()).min(0.99)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ray_takes_at_most_max_ray_samples_and_its_reach_grows_with_its_step() {
        // 5 cm steps on a 10 m ray: as asked.
        assert_eq!(ray_sampling(10.0, 0.05, 0.03), (200, 0.05, 0.03));
        // A metric step turned into 50 µm units by a scale typed in millimetres (1000 m per
        // unit): 10 m of ray would be 200 000 samples.
        let (samples, step, reach) = ray_sampling(10.0, 0.05e-3, 0.03e-3);
        assert!(samples <= MAX_RAY_SAMPLES + 1, "{samples} samples");
        assert!(
            (reach / step - 0.6).abs() < 1e-9,
            "step {step}, reach {reach}"
        );
    }

    #[test]
    fn the_coarser_samples_still_find_the_gaussian_in_the_way() {
        let mut splats = Splats::empty(0, 0);
        splats.push(
            glam::Vec3::new(0.0, 0.0, 5.0),
            glam::Vec3::ZERO,
            glam::Quat::IDENTITY,
            0.0,
            &[0.5; 3],
            &[],
            0,
            0,
        );
        let occlusion = Occlusion::new(&splats);
        // Ten units at a step of 1e-9 units: ten billion samples without the bound.
        let seen =
            occlusion.transmittance(DVec3::ZERO, DVec3::new(0.0, 0.0, 10.0), 0.1, 1e-9, 2e-9);
        // The coarser samples still find the Gaussian in the way (opacity 0.5 at its peak).
        assert!((seen - 0.5).abs() < 1e-6, "{seen}");
    }
}
