//! Adam over the splat parameter groups (3DGS's optimiser): per-group learning rates and on/off
//! switches, frozen Gaussians untouched (parameters and moments), optional visible-only
//! updates, and moment state that follows densification. In a focused run the moments can be
//! kept for the trainable Gaussians only (`Adam::for_trainable`), so the frozen rest costs
//! neither memory nor a pass of the update. Knows nothing of losses or images.

use glam::{Vec3, Vec4};

use super::schedule::ExponentialLr;
use crate::splats::Splats;
use update::{GroupLayout, Update, update_group, update_sh_groups};

mod update;

/// The trainable parameter groups, in the order of every `[_; 7]` array in this module.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ParamGroup {
    Means,
    LogScales,
    Rotations,
    RawOpacities,
    ShDc,
    ShRest,
    RawLabels,
}

impl ParamGroup {
    pub const ALL: [ParamGroup; 7] = [
        ParamGroup::Means,
        ParamGroup::LogScales,
        ParamGroup::Rotations,
        ParamGroup::RawOpacities,
        ParamGroup::ShDc,
        ParamGroup::ShRest,
        ParamGroup::RawLabels,
    ];

    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        match self {
            ParamGroup::Means => "means",
            ParamGroup::LogScales => "log_scales",
            ParamGroup::Rotations => "rotations",
            ParamGroup::RawOpacities => "raw_opacities",
            ParamGroup::ShDc => "sh_dc",
            ParamGroup::ShRest => "sh_rest",
            ParamGroup::RawLabels => "raw_labels",
        }
    }
}

/// Which groups are trained.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GroupFlags(pub [bool; 7]);

impl GroupFlags {
    pub const ALL_ON: GroupFlags = GroupFlags([true; 7]);
    pub const ALL_OFF: GroupFlags = GroupFlags([false; 7]);

    pub fn get(&self, g: ParamGroup) -> bool {
        self.0[g.index()]
    }

    pub fn set(&mut self, g: ParamGroup, on: bool) {
        self.0[g.index()] = on;
    }
}

impl Default for GroupFlags {
    fn default() -> Self {
        GroupFlags::ALL_ON
    }
}

/// Gradients in the splats' layout (raster's `SplatGrads` fields, borrowed).
#[derive(Clone, Copy, Debug)]
pub struct ParamGrads<'a> {
    pub v_means: &'a [Vec3],
    pub v_log_scales: &'a [Vec3],
    /// W.r.t. the un-normalised quaternion, glam order (x, y, z, w).
    pub v_rotations: &'a [Vec4],
    pub v_raw_opacities: &'a [f32],
    /// Same layout as `Splats::sh`.
    pub v_sh: &'a [f32],
    pub v_raw_labels: &'a [f32],
}

impl<'a> From<&'a crate::raster::SplatGrads> for ParamGrads<'a> {
    fn from(g: &'a crate::raster::SplatGrads) -> Self {
        ParamGrads {
            v_means: &g.v_means,
            v_log_scales: &g.v_log_scales,
            v_rotations: &g.v_rotations,
            v_raw_opacities: &g.v_raw_opacities,
            v_sh: &g.v_sh,
            v_raw_labels: &g.v_raw_labels,
        }
    }
}

/// Learning rates. Defaults are 3DGS's (`arguments/__init__.py`); the position rate is
/// multiplied by the scene extent and decays exponentially like `get_expon_lr_func`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct LearningRates {
    pub position_init: f32,
    pub position_final: f32,
    pub position_delay_mult: f32,
    /// Steps over which the position rate decays (3DGS 30 000; a run sets its iteration count).
    pub position_max_steps: u32,
    pub sh_dc: f32,
    pub sh_rest: f32,
    /// 0.05 as in the original 3DGS release and gsplat; 3DGS lowered it to 0.025 in 2024.
    /// Short CPU runs (2–3k steps) benefit from the faster opacity convergence.
    pub opacity: f32,
    pub log_scale: f32,
    pub rotation: f32,
    /// Label logits: not in 3DGS; a logit like opacity, trained a little slower so colour
    /// gradients that leak into label channels through shared geometry stay small.
    pub labels: f32,
}

impl Default for LearningRates {
    fn default() -> Self {
        LearningRates {
            position_init: 1.6e-4,
            position_final: 1.6e-6,
            position_delay_mult: 0.01,
            position_max_steps: 30_000,
            sh_dc: 2.5e-3,
            sh_rest: 2.5e-3 / 20.0,
            opacity: 0.05,
            log_scale: 5e-3,
            rotation: 1e-3,
            labels: 0.01,
        }
    }
}

impl LearningRates {
    /// The rate of each group at a 1-based step for a scene of the given extent.
    pub fn for_step(&self, step: u32, extent: f32) -> [f32; 7] {
        let position = ExponentialLr {
            init: self.position_init * extent,
            final_: self.position_final * extent,
            delay_steps: 0,
            delay_mult: self.position_delay_mult,
            max_steps: self.position_max_steps,
        };
        [
            position.at(step),
            self.log_scale,
            self.rotation,
            self.opacity,
            self.sh_dc,
            self.sh_rest,
            self.labels,
        ]
    }
}

/// First and second moments of one group, `per_gaussian` values per Gaussian.
#[derive(Clone, Debug, Default, PartialEq)]
struct Moments {
    m: Vec<f32>,
    v: Vec<f32>,
    step: u32,
    per_gaussian: usize,
}

impl Moments {
    fn zeros(n: usize, per_gaussian: usize) -> Moments {
        Moments {
            m: vec![0.0; n * per_gaussian],
            v: vec![0.0; n * per_gaussian],
            step: 0,
            per_gaussian,
        }
    }
}

/// Gaussians per rayon task: large enough that scheduling is negligible next to the update.
const GAUSSIANS_PER_TASK: usize = 2048;

/// Adam state for every group of one `Splats`.
#[derive(Clone, Debug, PartialEq)]
pub struct Adam {
    pub beta1: f32,
    pub beta2: f32,
    /// 1e-15 as 3DGS sets it (torch's default 1e-8 would damp the tiny position updates).
    pub eps: f32,
    /// Moments per slot: slot i is Gaussian i, or `listed[i]`.
    groups: [Moments; 7],
    /// Per group, an optional factor per Gaussian on its learning rate (see `set_rates`).
    rates: [Option<Vec<f32>>; 7],
    /// Gaussians of the splats.
    len: usize,
    /// The Gaussians that have moments, ascending (None: every one). Every other Gaussian is
    /// frozen: its moments would stay zero, so they are not kept (`for_trainable`).
    listed: Option<Vec<u32>>,
}

/// The first NaN/Inf an Adam step met, in group order: a gradient it applied, or a parameter it
/// produced. A non-finite gradient makes its moments and its parameter non-finite too, so
/// either way the model is damaged and must be restored. Gradients of Gaussians or groups the
/// step leaves alone (frozen, invisible, switched off) are not looked at: they change nothing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NonFinite {
    Gradient(ParamGroup),
    Parameter(ParamGroup),
}

impl std::fmt::Display for NonFinite {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NonFinite::Gradient(g) => write!(f, "gradient of {} is not finite", g.name()),
            NonFinite::Parameter(g) => write!(f, "{} became non-finite", g.name()),
        }
    }
}

impl Adam {
    /// Zero moments for every Gaussian of `splats`.
    pub fn new(splats: &Splats) -> Adam {
        Adam::with_slots(splats, None)
    }

    /// Zero moments for the Gaussians of `splats` not frozen (`meta.frozen`) only. A step never
    /// changes a frozen Gaussian's moments, so they would stay zero: a focused run (a block
    /// beside its frozen context, a refinement, a survey update) then keeps moments, and steps
    /// them, for what it trains, with the same results as `new`. The frozen set must not
    /// shrink afterwards: a Gaussian frozen here stays untouched even if unfrozen later.
    /// Gaussians appended later (densification's children) get moments.
    pub fn for_trainable(splats: &Splats) -> Adam {
        let frozen = &splats.meta.frozen;
        if !frozen.iter().any(|&f| f) {
            return Adam::new(splats);
        }
        let listed = (0..splats.len() as u32)
            .filter(|&g| !frozen[g as usize])
            .collect();
        Adam::with_slots(splats, Some(listed))
    }

    fn with_slots(splats: &Splats, listed: Option<Vec<u32>>) -> Adam {
        let n = splats.len();
        let slots = listed.as_ref().map_or(n, Vec::len);
        let k = splats.sh_coeffs();
        let per = [3, 3, 4, 1, 3, (k - 1) * 3, splats.label_channels];
        Adam {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
            groups: per.map(|p| Moments::zeros(slots, p)),
            rates: Default::default(),
            len: n,
            listed,
        }
    }

    /// The Gaussians that have moments, ascending (None: every one; see `for_trainable`).
    pub fn listed(&self) -> Option<&[u32]> {
        self.listed.as_deref()
    }

    /// The same state with moments for every Gaussian, zeros for those without (the layout of
    /// `new`): a reference for comparisons.
    pub fn with_every_gaussian(&self) -> Adam {
        let mut every = self.clone();
        let Some(list) = every.listed.take() else {
            return every;
        };
        for (to, from) in every.groups.iter_mut().zip(&self.groups) {
            let s = from.per_gaussian;
            to.m = vec![0.0; self.len * s];
            to.v = vec![0.0; self.len * s];
            for (slot, &g) in list.iter().enumerate() {
                let (at, from_at) = (g as usize * s, slot * s);
                to.m[at..at + s].copy_from_slice(&from.m[from_at..from_at + s]);
                to.v[at..at + s].copy_from_slice(&from.v[from_at..from_at + s]);
            }
        }
        every
    }

    /// The moments' slot of Gaussian `gaussian` (None: it has none, being frozen).
    fn slot(&self, gaussian: usize) -> Option<usize> {
        match &self.listed {
            None => Some(gaussian),
            Some(list) => list.binary_search(&(gaussian as u32)).ok(),
        }
    }

    /// Scales group `g`'s learning rate per Gaussian by `rates` (one factor per Gaussian; None:
    /// 1 for every one). Gaussians appended later get 1. Only the geometry groups (means,
    /// log-scales, rotations, opacities) take factors: the SH groups are updated fused.
    pub fn set_rates(&mut self, g: ParamGroup, rates: Option<Vec<f32>>) -> Result<(), String> {
        if matches!(g, ParamGroup::ShDc | ParamGroup::ShRest) {
            return Err(format!("{} takes no per-Gaussian rates", g.name()));
        }
        if let Some(r) = &rates
            && r.len() != self.len
        {
            return Err(format!(
                "{} rates: {} factors for {} Gaussians",
                g.name(),
                r.len(),
                self.len
            ));
        }
        self.rates[g.index()] = rates;
        Ok(())
    }

    /// Gaussians tracked.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Steps taken by a group (its bias-correction count).
    pub fn steps(&self, g: ParamGroup) -> u32 {
        self.groups[g.index()].step
    }

    /// One Adam step of every enabled group with the rates `lrs` (see `LearningRates::for_step`).
    /// Frozen Gaussians (`splats.meta.frozen`) and, if `visible` is given, invisible ones keep
    /// their parameters and moments (gsplat's "visible Adam"); otherwise updates are dense as in 3DGS.
    /// Returns the first NaN/Inf among the gradients it applied and the parameters it wrote; the
    /// step is then half done, and the caller restores a checkpoint.
    pub fn step(
        &mut self,
        splats: &mut Splats,
        grads: &ParamGrads,
        lrs: &[f32; 7],
        groups: &GroupFlags,
        visible: Option<&[bool]>,
    ) -> Option<NonFinite> {
        let n = splats.len();
        assert_eq!(self.len, n, "Adam state out of step with the splats");
        assert_eq!(splats.meta.frozen.len(), n, "frozen flags length");
        assert_eq!(grads.v_means.len(), n, "gradient length");
        assert_eq!(grads.v_sh.len(), splats.sh.len(), "SH gradient length");
        assert_eq!(
            grads.v_raw_labels.len(),
            splats.raw_labels.len(),
            "label gradient length"
        );
        let k3 = splats.sh_coeffs() * 3;
        assert_eq!(
            self.groups[ParamGroup::ShRest.index()].per_gaussian,
            k3 - 3,
            "SH degree changed under Adam"
        );
        if let Some(v) = visible {
            assert_eq!(v.len(), n, "visibility length");
        }
        let mut found = None;
        let (beta1, beta2, eps) = (self.beta1, self.beta2, self.eps);
        let update = |mom: &mut Moments, lr: f32, frozen, rate| {
            mom.step += 1;
            let t = mom.step as i32;
            Update {
                lr,
                beta1,
                beta2,
                eps,
                bias1: 1.0 - beta1.powi(t),
                bias2_sqrt: (1.0 - beta2.powi(t)).sqrt(),
                frozen,
                visible,
                rate,
            }
        };
        let listed = self.listed.as_deref();
        let (dc, rest) = (ParamGroup::ShDc.index(), ParamGroup::ShRest.index());
        let fuse_sh = groups.0[dc] && groups.0[rest] && k3 > 3;
        for group in ParamGroup::ALL {
            let gi = group.index();
            if !groups.0[gi] || (fuse_sh && group == ParamGroup::ShRest) {
                continue;
            }
            if fuse_sh && group == ParamGroup::ShDc {
                let (head, tail) = self.groups.split_at_mut(rest);
                let u_dc = update(&mut head[dc], lrs[dc], &splats.meta.frozen, None);
                let u_rest = update(&mut tail[0], lrs[rest], &splats.meta.frozen, None);
                let checks = update_sh_groups(
                    &mut splats.sh,
                    grads.v_sh,
                    (&mut head[dc], &mut tail[0]),
                    k3,
                    (u_dc, u_rest),
                    listed,
                );
                for (check, group) in checks
                    .into_iter()
                    .zip([ParamGroup::ShDc, ParamGroup::ShRest])
                {
                    if found.is_none() {
                        found = check.verdict(group);
                    }
                }
                continue;
            }
            let mom = &mut self.groups[gi];
            let u = update(mom, lrs[gi], &splats.meta.frozen, self.rates[gi].as_deref());
            let len = mom.per_gaussian;
            let layout = |stride, offset| GroupLayout {
                stride,
                offset,
                len,
            };
            let check = match group {
                ParamGroup::Means => {
                    let p: &mut [f32] = bytemuck::cast_slice_mut(&mut splats.means);
                    let g = bytemuck::cast_slice(grads.v_means);
                    update_group(p, g, mom, layout(3, 0), u, listed)
                }
                ParamGroup::LogScales => {
                    let p: &mut [f32] = bytemuck::cast_slice_mut(&mut splats.log_scales);
                    let g = bytemuck::cast_slice(grads.v_log_scales);
                    update_group(p, g, mom, layout(3, 0), u, listed)
                }
                ParamGroup::Rotations => {
                    let p: &mut [f32] = bytemuck::cast_slice_mut(&mut splats.rotations);
                    let g = bytemuck::cast_slice(grads.v_rotations);
                    update_group(p, g, mom, layout(4, 0), u, listed)
                }
                ParamGroup::RawOpacities => {
                    let (p, g) = (&mut splats.raw_opacities, grads.v_raw_opacities);
                    update_group(p, g, mom, layout(1, 0), u, listed)
                }
                ParamGroup::ShDc => {
                    update_group(&mut splats.sh, grads.v_sh, mom, layout(k3, 0), u, listed)
                }
                ParamGroup::ShRest => {
                    update_group(&mut splats.sh, grads.v_sh, mom, layout(k3, 3), u, listed)
                }
                ParamGroup::RawLabels => {
                    let c = splats.label_channels;
                    let (p, g) = (&mut splats.raw_labels, grads.v_raw_labels);
                    update_group(p, g, mom, layout(c, 0), u, listed)
                }
            };
            if found.is_none() {
                found = check.verdict(group);
            }
        }
        found
    }

    /// Zero moments for `n` Gaussians appended at the end (3DGS `densification_postfix`).
    pub fn append(&mut self, n: usize) {
        for g in &mut self.groups {
            let new = g.m.len() + n * g.per_gaussian;
            g.m.resize(new, 0.0);
            g.v.resize(new, 0.0);
        }
        for r in self.rates.iter_mut().flatten() {
            r.resize(r.len() + n, 1.0);
        }
        if let Some(list) = &mut self.listed {
            list.extend(self.len as u32..(self.len + n) as u32);
        }
        self.len += n;
    }

    /// Keeps the moments of Gaussians where `keep[g]` (the mask given to `Splats::retain`).
    pub fn retain(&mut self, keep: &[bool]) {
        assert_eq!(keep.len(), self.len, "retain mask length");
        // Whether each slot's Gaussian stays, and the listed Gaussians' new indices.
        let kept_slots: Vec<bool> = match &mut self.listed {
            None => keep.to_vec(),
            Some(list) => {
                let kept: Vec<bool> = list.iter().map(|&g| keep[g as usize]).collect();
                let mut new_index = Vec::with_capacity(keep.len());
                let mut next = 0u32;
                for &k in keep {
                    new_index.push(next);
                    next += u32::from(k);
                }
                let mut slots = kept.iter();
                list.retain(|_| slots.next().copied().unwrap_or(false));
                list.iter_mut().for_each(|g| *g = new_index[*g as usize]);
                kept
            }
        };
        for g in &mut self.groups {
            let s = g.per_gaussian;
            let mut w = 0;
            for (i, &k) in kept_slots.iter().enumerate() {
                if k {
                    g.m.copy_within(i * s..(i + 1) * s, w * s);
                    g.v.copy_within(i * s..(i + 1) * s, w * s);
                    w += 1;
                }
            }
            g.m.truncate(w * s);
            g.v.truncate(w * s);
        }
        for r in self.rates.iter_mut().flatten() {
            let mut kept = keep.iter();
            r.retain(|_| kept.next().copied().unwrap_or(false));
        }
        self.len = keep.iter().filter(|&&k| k).count();
    }

    /// Zeroes a group's moments (3DGS `replace_tensor_to_optimizer` after an opacity reset).
    pub fn reset_group(&mut self, g: ParamGroup) {
        let mom = &mut self.groups[g.index()];
        mom.m.fill(0.0);
        mom.v.fill(0.0);
    }

    /// A group's first and second moments, `per_gaussian` values per Gaussian (per listed
    /// Gaussian when only some have moments: `listed`).
    pub fn moments(&self, g: ParamGroup) -> (&[f32], &[f32]) {
        let mom = &self.groups[g.index()];
        (&mom.m, &mom.v)
    }

    /// Counts one step of every enabled group without touching moments or parameters (a GPU
    /// step applies it) and returns per group its bias corrections `(1 - β1^t, sqrt(1 - β2^t))`
    /// this step, None for a group switched off: the same counts `step` keeps.
    pub fn advance(&mut self, groups: &GroupFlags) -> [Option<(f32, f32)>; 7] {
        let (beta1, beta2) = (self.beta1, self.beta2);
        std::array::from_fn(|gi| {
            if !groups.0[gi] {
                return None;
            }
            let mom = &mut self.groups[gi];
            mom.step += 1;
            let t = mom.step as i32;
            Some((1.0 - beta1.powi(t), (1.0 - beta2.powi(t)).sqrt()))
        })
    }

    /// Replaces a group's moments (from a GPU step); the lengths must match.
    pub fn set_moments(&mut self, g: ParamGroup, m: Vec<f32>, v: Vec<f32>) -> Result<(), String> {
        let mom = &mut self.groups[g.index()];
        if m.len() != mom.m.len() || v.len() != mom.v.len() {
            return Err(format!(
                "{} moments: {} and {} values for {}",
                g.name(),
                m.len(),
                v.len(),
                mom.m.len()
            ));
        }
        mom.m = m;
        mom.v = v;
        Ok(())
    }

    /// Scales a group's moments as if every gradient it has seen had been `factor` times as
    /// large: `m · factor`, `v · factor²`. Adam's step does not depend on the gradients' scale
    /// (up to `eps`), so the next steps are those the unscaled gradients would have given.
    pub fn scale_moments(&mut self, g: ParamGroup, factor: f32) {
        let mom = &mut self.groups[g.index()];
        mom.m.iter_mut().for_each(|m| *m *= factor);
        mom.v.iter_mut().for_each(|v| *v *= factor * factor);
    }

    /// Zeroes the moments of one Gaussian in one group (nothing for a Gaussian without: they
    /// are zero).
    pub fn reset_gaussian(&mut self, g: ParamGroup, gaussian: usize) {
        let Some(slot) = self.slot(gaussian) else {
            return;
        };
        let mom = &mut self.groups[g.index()];
        let s = mom.per_gaussian;
        mom.m[slot * s..(slot + 1) * s].fill(0.0);
        mom.v[slot * s..(slot + 1) * s].fill(0.0);
    }
}

#[cfg(test)]
mod tests;
