//! Adaptive density control exactly as 3DGS (`densify_and_prune`, `reset_opacity`): clone small
//! and split large Gaussians whose mean 2D gradient is high, prune transparent and oversized
//! ones, reset opacities; optionally under a Gaussian budget. Frozen Gaussians are never touched.

use glam::{Quat, Vec3};

use super::adam::{Adam, ParamGroup};
use crate::splats::Splats;
use crate::splats::model::{logit, sigmoid};

/// When and how to densify. Steps are 1-based like 3DGS's `iteration`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct DensifyConfig {
    /// Densify at steps strictly after `start` (3DGS `densify_from_iter` 500) ...
    pub start: u32,
    /// ... and strictly before `stop` (`densify_until_iter` 15 000), every `every` (100) steps.
    pub stop: u32,
    pub every: u32,
    /// Mean 2D-mean gradient norm (NDC units) above which a Gaussian is densified (0.0002).
    pub grad_threshold: f32,
    /// Gaussians with max scale ≤ `percent_dense · extent` are cloned, larger ones split (0.01).
    pub percent_dense: f32,
    /// Samples per split Gaussian (N = 2); their scale is divided by `0.8·N` (= 1.6).
    pub split_count: usize,
    /// Prune below this opacity (0.005).
    pub min_opacity: f32,
    /// After the first opacity reset, prune Gaussians whose largest world scale exceeds this
    /// fraction of the extent (0.1)...
    pub max_world_fraction: f32,
    /// ... or, when set, whose screen radius exceeded this many pixels since the last densify
    /// pass (3DGS's `max_screen_size`, 20). Off by default: in the official 3DGS code the radii
    /// are zeroed by the clone/split step before the prune reads them (graphdeco-inria/
    /// gaussian-splatting#123), so this prune never fires there, and gsplat disables it. A
    /// pixel limit also depends on the resolution: at 480×270, 20 px pruned 31k of 51k
    /// Gaussians of the demo building in one pass.
    pub max_screen_size: Option<f32>,
    /// Opacity reset period (3000; 0 = never) and the cap it applies (0.01).
    pub opacity_reset_every: u32,
    pub opacity_reset_value: f32,
    /// Also reset at `start` (3DGS does this for white-background scenes).
    pub reset_opacity_at_start: bool,
    /// Cap on the Gaussian count: densify the highest gradients first until the cap.
    pub budget: Option<usize>,
    /// When set, the trainer prunes the model to this many Gaussians by importance (blending
    /// weight over the training views, `train::importance`) at step `prune_at`, then trains on
    /// (`--budget`). The densifier itself never reads it.
    pub prune_to: Option<usize>,
    /// The step of that prune; `None`: the end of the densification window (`stop`). Either is
    /// brought forward to the run's last step when the run ends first.
    pub prune_at: Option<u32>,
    pub seed: u64,
}

impl Default for DensifyConfig {
    fn default() -> Self {
        DensifyConfig {
            start: 500,
            stop: 15_000,
            every: 100,
            grad_threshold: 0.0002,
            percent_dense: 0.01,
            split_count: 2,
            min_opacity: 0.005,
            max_world_fraction: 0.1,
            max_screen_size: None,
            opacity_reset_every: 3000,
            opacity_reset_value: 0.01,
            reset_opacity_at_start: false,
            budget: None,
            prune_to: None,
            prune_at: None,
            seed: 0,
        }
    }
}

/// What one `after_step` did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DensifyReport {
    /// True when a densify-and-prune pass ran this step.
    pub densified: bool,
    pub cloned: usize,
    /// Gaussians split (each replaced by `split_count` new ones).
    pub split: usize,
    /// Gaussians removed by pruning (not counting split parents).
    pub pruned: usize,
    pub opacity_reset: bool,
}

/// Densification statistics and the seeded generator for split samples.
#[derive(Clone, Debug)]
pub struct Densifier {
    pub config: DensifyConfig,
    /// Σ of 2D-mean gradient norms over the steps a Gaussian was visible (`xyz_gradient_accum`).
    grad_accum: Vec<f32>,
    /// Steps a Gaussian was visible (`denom`).
    visible_count: Vec<u32>,
    /// Largest screen radius seen, px (`max_radii2D`).
    max_radii: Vec<f32>,
    rng: fastrand::Rng,
}

/// 3DGS scene extent (`getNerfppNorm`): 1.1 × the largest distance of a camera centre from
/// their mean. Position learning rates and the clone/split/prune sizes scale with it.
pub fn camera_extent(centres: &[Vec3]) -> f32 {
    if centres.is_empty() {
        return 1.0;
    }
    let mean = centres.iter().copied().sum::<Vec3>() / centres.len() as f32;
    let max = centres
        .iter()
        .map(|c| c.distance(mean))
        .fold(0.0f32, f32::max);
    1.1 * max
}

/// A standard normal sample (Box–Muller; `1 - u` keeps the logarithm finite).
fn normal(rng: &mut fastrand::Rng) -> f32 {
    let u1 = 1.0 - rng.f32();
    let u2 = rng.f32();
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

impl Densifier {
    /// Statistics for `n` Gaussians, all zero.
    pub fn new(config: DensifyConfig, n: usize) -> Densifier {
        let rng = fastrand::Rng::with_seed(config.seed);
        let mut d = Densifier {
            config,
            grad_accum: Vec::new(),
            visible_count: Vec::new(),
            max_radii: Vec::new(),
            rng,
        };
        d.reset_stats(n);
        d
    }

    /// Zeroes the statistics for `n` Gaussians (after the model was changed from outside).
    pub fn reset_stats(&mut self, n: usize) {
        self.grad_accum.clear();
        self.grad_accum.resize(n, 0.0);
        self.visible_count.clear();
        self.visible_count.resize(n, 0);
        self.max_radii.clear();
        self.max_radii.resize(n, 0.0);
    }

    /// Adds one step's statistics (3DGS `add_densification_stats` and the `max_radii2D`
    /// update): Gaussians with radius > 0 count as visible.
    pub fn accumulate(&mut self, v_means2d_norm: &[f32], radii: &[u32]) {
        assert_eq!(
            v_means2d_norm.len(),
            self.grad_accum.len(),
            "densify stats length"
        );
        assert_eq!(radii.len(), self.grad_accum.len(), "densify radii length");
        for (g, (&norm, &r)) in v_means2d_norm.iter().zip(radii).enumerate() {
            if r > 0 {
                self.grad_accum[g] += norm;
                self.visible_count[g] += 1;
                self.max_radii[g] = self.max_radii[g].max(r as f32);
            }
        }
    }

    /// Adds statistics gathered elsewhere (the GPU's Adam kernel does `accumulate`'s sums).
    pub fn add_stats(&mut self, grad_accum: &[f32], visible_count: &[u32], max_radii: &[f32]) {
        assert_eq!(
            grad_accum.len(),
            self.grad_accum.len(),
            "densify stats length"
        );
        for (g, ((&grad, &count), &radius)) in grad_accum
            .iter()
            .zip(visible_count)
            .zip(max_radii)
            .enumerate()
        {
            self.grad_accum[g] += grad;
            self.visible_count[g] += count;
            self.max_radii[g] = self.max_radii[g].max(radius);
        }
    }

    /// Whether `after_step(step, ..)` changes anything (densifies, prunes or resets opacity).
    pub fn due(&self, step: u32) -> bool {
        let c = &self.config;
        step < c.stop
            && ((step > c.start && c.every > 0 && step.is_multiple_of(c.every))
                || (c.opacity_reset_every > 0 && step.is_multiple_of(c.opacity_reset_every))
                || (c.reset_opacity_at_start && step == c.start))
    }

    /// Mean gradient norm per Gaussian over the steps it was visible (0 if never).
    pub fn mean_grads(&self) -> Vec<f32> {
        self.grad_accum
            .iter()
            .zip(&self.visible_count)
            .map(|(&a, &c)| if c > 0 { a / c as f32 } else { 0.0 })
            .collect()
    }

    /// Runs what is due at `step` (call once per step, after the optimiser): densify-and-prune
    /// every `every` steps in `(start, stop)`, opacity reset every `opacity_reset_every` steps
    /// before `stop`. Keeps `adam` aligned with `splats`.
    pub fn after_step(
        &mut self,
        step: u32,
        splats: &mut Splats,
        adam: &mut Adam,
        extent: f32,
    ) -> DensifyReport {
        let mut report = DensifyReport::default();
        let c = &self.config;
        if step >= c.stop {
            return report;
        }
        if step > c.start && c.every > 0 && step.is_multiple_of(c.every) {
            // Size pruning only once opacities have been reset (3DGS `size_threshold`).
            let prune_large = c.opacity_reset_every > 0 && step > c.opacity_reset_every;
            report = self.densify_and_prune(splats, adam, extent, prune_large);
        }
        let c = &self.config;
        let periodic = c.opacity_reset_every > 0 && step.is_multiple_of(c.opacity_reset_every);
        if periodic || (c.reset_opacity_at_start && step == c.start) {
            self.reset_opacity(splats, adam);
            report.opacity_reset = true;
        }
        report
    }

    /// Caps every trainable opacity at `opacity_reset_value` and zeroes its Adam moments.
    pub fn reset_opacity(&self, splats: &mut Splats, adam: &mut Adam) {
        let cap = logit(self.config.opacity_reset_value);
        for g in 0..splats.len() {
            if splats.meta.frozen[g] {
                continue;
            }
            let raw = &mut splats.raw_opacities[g];
            // min in opacity space, as 3DGS (`inverse_sigmoid(min(opacity, 0.01))`); lower
            // opacities keep their exact logit instead of a sigmoid/logit round trip.
            if sigmoid(*raw) > self.config.opacity_reset_value {
                *raw = cap;
            }
            adam.reset_gaussian(ParamGroup::RawOpacities, g);
        }
    }

    /// Clone, split, then prune (3DGS `densify_and_prune`); statistics are zeroed afterwards.
    /// `prune_large` adds the size prunes (world scale, and screen radius when configured) to
    /// the opacity prune.
    pub fn densify_and_prune(
        &mut self,
        splats: &mut Splats,
        adam: &mut Adam,
        extent: f32,
        prune_large: bool,
    ) -> DensifyReport {
        let n0 = splats.len();
        assert_eq!(
            self.grad_accum.len(),
            n0,
            "densify stats out of step with the splats"
        );
        assert_eq!(adam.len(), n0, "Adam out of step with the splats");
        let c = self.config.clone();
        let grads = self.mean_grads();
        let dense_limit = c.percent_dense * extent;
        let max_scale: Vec<f32> = splats
            .log_scales
            .iter()
            .map(|l| l.max_element().exp())
            .collect();
        // `!(g < threshold)` would take NaN; gradients here are finite means, so >= is exact.
        let mut clone_sel = vec![false; n0];
        let mut split_sel = vec![false; n0];
        for g in 0..n0 {
            if splats.meta.frozen[g] || !(grads[g] >= c.grad_threshold) {
                continue;
            }
            if max_scale[g] <= dense_limit {
                clone_sel[g] = true;
            } else {
                split_sel[g] = true;
            }
        }
        if let Some(budget) = c.budget {
            self.apply_budget(budget, n0, &grads, &mut clone_sel, &mut split_sel);
        }

        let mut next_id = splats.meta.next_id();
        let k3 = splats.sh_coeffs() * 3;
        let lc = splats.label_channels;
        let mut sh = vec![0.0f32; k3];
        let mut labels = vec![0.0f32; lc];
        let mut push_copy = |s: &mut Splats, g: usize, mean: Vec3, log_scale: Vec3, id: u64| {
            sh.copy_from_slice(s.sh_of(g));
            labels.copy_from_slice(s.labels_of(g));
            let (rot, op, survey) = (s.rotations[g], s.raw_opacities[g], s.meta.survey[g]);
            s.push(mean, log_scale, rot, op, &sh, &labels, id, survey);
            // A child keeps its parent's history and state (a refined crack's children are
            // refined crack too).
            let child = s.len() - 1;
            s.meta.damage_survey[child] = s.meta.damage_survey[g];
            s.meta.state[child] = s.meta.state[g];
        };
        // Clones: exact copies appended in index order (3DGS `densify_and_clone`).
        let mut cloned = 0;
        for g in (0..n0).filter(|&g| clone_sel[g]) {
            let (mean, ls) = (splats.means[g], splats.log_scales[g]);
            push_copy(splats, g, mean, ls, next_id);
            next_id += 1;
            cloned += 1;
        }
        // Splits: N rounds over the selection (torch `repeat(N, 1)` order), each child drawn from
        // the parent Gaussian, scale divided by 0.8·N (3DGS `densify_and_split`).
        let split_idx: Vec<usize> = (0..n0).filter(|&g| split_sel[g]).collect();
        let shrink = (0.8 * c.split_count as f32).ln();
        for _ in 0..c.split_count {
            for &g in &split_idx {
                let std = splats.log_scales[g].exp();
                let local = Vec3::new(
                    normal(&mut self.rng),
                    normal(&mut self.rng),
                    normal(&mut self.rng),
                ) * std;
                let q = splats.rotations[g];
                let q = if q.length_squared() > 0.0 {
                    q.normalize()
                } else {
                    Quat::IDENTITY
                };
                let mean = splats.means[g] + q * local;
                let ls = splats.log_scales[g] - Vec3::splat(shrink);
                push_copy(splats, g, mean, ls, next_id);
                next_id += 1;
            }
        }
        let n1 = splats.len();
        adam.append(n1 - n0);

        // Prune over the grown population; new Gaussians have not been seen on screen yet.
        let world_limit = c.max_world_fraction * extent;
        let mut keep = vec![true; n1];
        let mut pruned = 0;
        for (g, k) in keep.iter_mut().enumerate() {
            if splats.meta.frozen[g] {
                continue;
            }
            if g < n0 && split_sel[g] {
                *k = false;
                continue;
            }
            let transparent = sigmoid(splats.raw_opacities[g]) < c.min_opacity;
            let too_big = prune_large && {
                let screen = if g < n0 { self.max_radii[g] } else { 0.0 };
                c.max_screen_size.is_some_and(|limit| screen > limit)
                    || splats.log_scales[g].max_element().exp() > world_limit
            };
            if transparent || too_big {
                *k = false;
                pruned += 1;
            }
        }
        splats.retain(&keep);
        adam.retain(&keep);
        self.reset_stats(splats.len());
        DensifyReport {
            densified: true,
            cloned,
            split: split_idx.len(),
            pruned,
            opacity_reset: false,
        }
    }

    /// Keeps the highest-gradient candidates whose growth (1 per clone, N-1 per split) fits
    /// under `budget`; ties go to the lower index so the choice is deterministic.
    fn apply_budget(
        &self,
        budget: usize,
        n0: usize,
        grads: &[f32],
        clone_sel: &mut [bool],
        split_sel: &mut [bool],
    ) {
        let mut capacity = budget.saturating_sub(n0);
        let mut candidates: Vec<usize> =
            (0..n0).filter(|&g| clone_sel[g] || split_sel[g]).collect();
        candidates.sort_by(|&a, &b| grads[b].total_cmp(&grads[a]).then(a.cmp(&b)));
        for g in candidates {
            let cost = if clone_sel[g] {
                1
            } else {
                self.config.split_count.saturating_sub(1)
            };
            if cost <= capacity {
                capacity -= cost;
            } else {
                clone_sel[g] = false;
                split_sel[g] = false;
            }
        }
    }
}

#[cfg(test)]
mod tests;
