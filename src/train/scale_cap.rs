//! A bound on how far a run may grow each Gaussian it trains: every axis of a trainable
//! Gaussian's log-scale stays within `ln(growth)` of its value when the run started, applied
//! after each optimiser step. A fine-tune of a trained twin (the timeline's update) has nothing
//! else holding a Gaussian near its start: with from-scratch rates, neighbours of the damage grew
//! into metre-long, opaque streaks that fit the new photos inside their hulls and spoiled the
//! earlier views (docs/TIMELINE.md). Keyed by Gaussian id, so densification may reorder freely;
//! Gaussians created during the run are not bounded.

use glam::Vec3;

use crate::splats::Splats;

#[derive(Clone, Debug)]
pub struct ScaleCap {
    /// Ids of the bounded Gaussians, ascending, and each one's largest log-scale per axis.
    ids: Vec<u64>,
    caps: Vec<Vec3>,
}

impl ScaleCap {
    /// Bounds the Gaussians of `splats` that `trainable` names to `growth` × their current size.
    pub fn new(splats: &Splats, trainable: impl Fn(usize) -> bool, growth: f32) -> ScaleCap {
        let ln = growth.max(1.0).ln();
        let mut bounded: Vec<(u64, Vec3)> = (0..splats.len())
            .filter(|&g| trainable(g))
            .map(|g| (splats.meta.ids[g], splats.log_scales[g] + Vec3::splat(ln)))
            .collect();
        bounded.sort_by_key(|&(id, _)| id);
        ScaleCap {
            ids: bounded.iter().map(|&(id, _)| id).collect(),
            caps: bounded.iter().map(|&(_, cap)| cap).collect(),
        }
    }

    /// Clamps every bounded Gaussian's log-scales to its cap.
    pub fn apply(&self, splats: &mut Splats) {
        if self.ids.is_empty() {
            return;
        }
        for (log_scale, id) in splats.log_scales.iter_mut().zip(&splats.meta.ids) {
            if let Ok(i) = self.ids.binary_search(id) {
                *log_scale = log_scale.min(self.caps[i]);
            }
        }
    }

    /// How many Gaussians are bounded.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    #[test]
    fn trained_gaussians_stay_within_their_growth_and_others_are_free() {
        let mut splats = Splats::empty(0, 0);
        for id in 0..3 {
            splats.push(
                Vec3::ZERO,
                Vec3::splat(-3.0),
                Quat::IDENTITY,
                0.0,
                &[0.5; 3],
                &[],
                id,
                0,
            );
        }
        let cap = ScaleCap::new(&splats, |g| g != 1, 2.0);
        assert_eq!(cap.len(), 2);
        // Reordered (as densification may) and grown.
        splats.log_scales = vec![Vec3::new(-1.0, -3.5, -3.0); 3];
        splats.meta.ids.reverse();
        cap.apply(&mut splats);
        let limit = -3.0 + 2f32.ln();
        for g in 0..3 {
            let s = splats.log_scales[g];
            if splats.meta.ids[g] == 1 {
                assert_eq!(s.x, -1.0, "not bounded");
            } else {
                assert!((s.x - limit).abs() < 1e-6, "{s}");
                assert_eq!((s.y, s.z), (-3.5, -3.0), "shrinking and staying are free");
            }
        }
    }
}
