//! `TrainSpec`: everything one training run is steered by (DESIGN.md "The trainer is steerable").
//! Refinement and survey updates are configurations of this, not new trainers. Pure settings:
//! no pixels (those live in `TrainView`), no loop (that is `trainer.rs`).

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::scene::project::ColourTransform;
use crate::scene::{Camera, Mask, RgbImage};
use crate::train::adam::{GroupFlags, LearningRates, ParamGroup};
use crate::train::densify::DensifyConfig;

/// Which parameter groups the optimiser may change. A group switched off keeps its values and
/// its gradients are never computed into the update.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ParamGroups {
    pub means: bool,
    pub log_scales: bool,
    pub rotations: bool,
    pub raw_opacities: bool,
    /// SH degree 0 coefficient (base colour).
    pub sh_dc: bool,
    /// SH degrees 1..=3 (view-dependent colour).
    pub sh_rest: bool,
    pub raw_labels: bool,
}

impl ParamGroups {
    pub const ALL: ParamGroups = ParamGroups {
        means: true,
        log_scales: true,
        rotations: true,
        raw_opacities: true,
        sh_dc: true,
        sh_rest: true,
        raw_labels: true,
    };

    /// Only the damage labels: geometry and colour stay as they are.
    pub const LABELS_ONLY: ParamGroups = ParamGroups {
        means: false,
        log_scales: false,
        rotations: false,
        raw_opacities: false,
        sh_dc: false,
        sh_rest: false,
        raw_labels: true,
    };

    /// The optimiser's per-group switches.
    pub fn flags(&self) -> GroupFlags {
        let mut flags = GroupFlags::ALL_ON;
        flags.set(ParamGroup::Means, self.means);
        flags.set(ParamGroup::LogScales, self.log_scales);
        flags.set(ParamGroup::Rotations, self.rotations);
        flags.set(ParamGroup::RawOpacities, self.raw_opacities);
        flags.set(ParamGroup::ShDc, self.sh_dc);
        flags.set(ParamGroup::ShRest, self.sh_rest);
        flags.set(ParamGroup::RawLabels, self.raw_labels);
        flags
    }
}

impl Default for ParamGroups {
    fn default() -> Self {
        ParamGroups::ALL
    }
}

/// Learning-rate overrides; `None` keeps the DESIGN.md / 3DGS default (`LearningRates`; the
/// position rates are multiplied by the scene extent like the defaults).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LrOverrides {
    /// Initial position rate (before the × extent).
    pub means: Option<f32>,
    /// Final position rate of the exponential decay (before the × extent).
    pub means_final: Option<f32>,
    pub log_scales: Option<f32>,
    pub rotations: Option<f32>,
    pub raw_opacities: Option<f32>,
    pub sh_dc: Option<f32>,
    pub sh_rest: Option<f32>,
    pub raw_labels: Option<f32>,
}

impl LrOverrides {
    /// Replaces the rates this overrides in `lrs`.
    pub fn apply(&self, lrs: &mut LearningRates) {
        let set = |target: &mut f32, value: Option<f32>| {
            if let Some(v) = value {
                *target = v;
            }
        };
        set(&mut lrs.position_init, self.means);
        set(&mut lrs.position_final, self.means_final);
        set(&mut lrs.log_scale, self.log_scales);
        set(&mut lrs.rotation, self.rotations);
        set(&mut lrs.opacity, self.raw_opacities);
        set(&mut lrs.sh_dc, self.sh_dc);
        set(&mut lrs.sh_rest, self.sh_rest);
        set(&mut lrs.labels, self.raw_labels);
    }
}

/// Gentler rates, a continuation rather than a restart: position 1.6e-5 × extent, log-scale
/// 1e-3, opacity 0.01. `compact`'s fine-tune moves at them; for the update (`twin update
/// --gentle-rates`) they keep the earlier views 0.7 dB better still but learn 7.7 m less of the
/// new cracks on the demo, so they are not the update's default.
pub fn gentle_learning_rates() -> LrOverrides {
    LrOverrides {
        means: Some(1.6e-5),
        log_scales: Some(1e-3),
        raw_opacities: Some(0.01),
        ..Default::default()
    }
}

/// 3DGS adaptive density control with its windows fitted to a run of `iterations` steps: 3DGS
/// densifies from 500 to 15 000 of 30 000 steps, every 100, resetting opacity every 3 000. Short
/// runs keep the 100-step rhythm (gradient statistics need that many views), start after a
/// sixth of the run at most, stop at half of it, and reset opacity once, early enough that
/// opacities recover before the end.
pub fn densify_for_iterations(iterations: u32, seed: u64) -> DensifyConfig {
    let full = iterations >= 30_000;
    DensifyConfig {
        start: 500.min(iterations / 6),
        stop: if full { 15_000 } else { iterations / 2 },
        every: 100,
        opacity_reset_every: if full { 3000 } else { (iterations / 3).max(1) },
        seed,
        ..DensifyConfig::default()
    }
}

/// How far density control may grow a `--budget` run above its budget before the importance
/// prune cuts it back (Mini-Splatting's densify-then-simplify): the prune chooses among this
/// many times the budget. On lego at 1/2 scale 3 scored as 2 (the unbudgeted run grows to about
/// twice the budget anyway) and 1.5 lower (34.07 against 34.15 dB).
pub const BUDGET_OVERSHOOT: f32 = 2.0;

/// Where in a `--budget` run the importance prune happens, as a fraction of the run: after
/// densification (the first half) has ended and the overgrown model has trained on, early
/// enough for the pruned one to recover. Against the end of densification (1/2): lego at 1/2
/// scale 34.18 against 34.15 dB (10 000 steps), the demo at 1/4 scale 30.26 against 29.97 dB,
/// lego at 1/8 33.31 against 33.29 dB (10 000 steps) and 31.24 against 31.16 dB (3 000 steps,
/// four seeds); the demo at 1/8 scale, where no setting comes near the full run, 29.89 against
/// 30.09 dB (docs/ENGINE.md, "Gaussian budget").
pub const BUDGET_PRUNE_AT: f32 = 0.75;

/// Density control for a run that must end with at most `budget` Gaussians: 3DGS density control
/// fitted to the run and capped at `BUDGET_OVERSHOOT × budget` (highest gradients first), then an
/// importance prune to `budget` at `BUDGET_PRUNE_AT` of the run (`DensifyConfig::prune_to`,
/// `prune_at`).
pub fn densify_for_budget(iterations: u32, budget: usize, seed: u64) -> DensifyConfig {
    let adaptive = densify_for_iterations(iterations, seed);
    let prune_at = (iterations as f32 * BUDGET_PRUNE_AT).round() as u32;
    DensifyConfig {
        budget: Some((budget as f32 * BUDGET_OVERSHOOT).ceil() as usize),
        prune_to: Some(budget),
        prune_at: Some(prune_at.max(adaptive.stop)),
        ..adaptive
    }
}

/// How the Gaussian set may change during a run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum DensifyPolicy {
    /// A fixed set: refinement of frozen geometry, label-only training.
    Off,
    /// 3DGS adaptive density control (its `budget` may cap the count).
    Adaptive(DensifyConfig),
    /// Adaptive density control fitted to the run, capped at `max` Gaussians.
    Budget { max: usize },
}

/// The label loss's weight, relative to its set weight, once it no longer shapes the geometry
/// (`Targets::label_geometry_steps`): a power of two, so the scaling is exact, and small enough
/// that what reaches the geometry is noise beside the photometric gradient. Adam's moments of
/// the label logits are scaled with it, so their steps stay what the full loss gives.
pub const DETACHED_LABEL_SCALE: f32 = 1.0 / 4096.0;

/// What the loss compares the render to. RGB uses each view's `image` (an overlay target is just
/// another RGB image, built by the damage module); labels use each view's per-class masks.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Targets {
    /// Weight of the photometric loss `(1-λ)·L1 + λ·(1-SSIM)`; 0 disables it.
    pub rgb_weight: f32,
    /// λ of D-SSIM (DESIGN.md: 0.2).
    pub ssim_lambda: f32,
    /// Weight of the per-class binary cross-entropy on label channels; 0 disables it.
    pub label_weight: f32,
    /// Weight of damage pixels inside the cross-entropy: damage is rare and thin, and a Gaussian
    /// straddling a one-pixel crack sees mostly background, so > 1 keeps recall up.
    #[serde(default = "default_pos_weight")]
    pub label_pos_weight: f32,
    /// Steps during which the label loss shapes the geometry (None: the whole run). After them
    /// its gradient reaches positions, shapes and opacities only scaled by
    /// [`DETACHED_LABEL_SCALE`], while the label logits keep the steps the
    /// full loss gives them: the views' consensus forms the damage's geometry first, and what
    /// a long run would add is each view's own mask errors (docs/DAMAGE.md, mask-noise study).
    #[serde(default)]
    pub label_geometry_steps: Option<u32>,
}

fn default_pos_weight() -> f32 {
    1.0
}

impl Default for Targets {
    fn default() -> Self {
        Targets {
            rgb_weight: 1.0,
            ssim_lambda: 0.2,
            label_weight: 0.0,
            label_pos_weight: default_pos_weight(),
            label_geometry_steps: None,
        }
    }
}

/// One training run's settings. Resolution is not one of them: it is a property of the views
/// given to the trainer (`TrainView`), loaded at whatever scale their caller chose.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainSpec {
    /// Indices into the training views given to the trainer; `None` means all of them.
    pub views: Option<Vec<usize>>,
    pub iterations: u32,
    /// Per Gaussian of the initial model: which ones may change (the rest are frozen but still
    /// rendered). `None`: every Gaussian not marked frozen in `SplatMeta`. Gaussians created by
    /// densification are trainable.
    pub trainable: Option<Vec<bool>>,
    pub groups: ParamGroups,
    pub targets: Targets,
    pub densify: DensifyPolicy,
    pub lr: LrOverrides,
    /// Final SH degree; the active degree ramps up by one every `sh_ramp_every` steps (3DGS: 1000
    /// of 30k).
    pub sh_degree: u32,
    pub sh_ramp_every: u32,
    pub background: Vec3,
    pub seed: u64,
    /// Steps between held-out evaluations (0: only at the end).
    pub eval_every: u32,
    /// Each trainable Gaussian's scale stays within this factor of its size at the start
    /// (`scale_cap`; None: unbounded, as in a from-scratch run).
    pub max_scale_growth: Option<f32>,
    /// Learn each training photo's light (`appearance`; None: the photos as they are).
    pub appearance: Option<crate::train::appearance::AppearanceConfig>,
    /// Per Gaussian of the initial model, a factor on its position, scale, rotation and opacity
    /// rates (None: 1 for every one; Gaussians created by densification get 1). The timeline's
    /// update continues the twin's Gaussians gently while its new-damage seeds learn at full rates.
    #[serde(default)]
    pub geometry_rate: Option<Vec<f32>>,
    /// The renderer the run trains on (CPU by default).
    #[serde(default)]
    pub backend: crate::train::backend_choice::Backend,
    /// Stop before `iterations` once the loss stops improving (`plateau`; None: run them all).
    #[serde(default)]
    pub stop_when_flat: Option<crate::train::plateau::Plateau>,
}

impl TrainSpec {
    /// The default from-scratch reconstruction: every view, adaptive density control, SH degree 3.
    pub fn reconstruction(iterations: u32) -> TrainSpec {
        TrainSpec {
            views: None,
            iterations,
            trainable: None,
            groups: ParamGroups::ALL,
            targets: Targets::default(),
            densify: DensifyPolicy::Adaptive(densify_for_iterations(iterations, 0)),
            lr: LrOverrides::default(),
            sh_degree: 3,
            sh_ramp_every: (iterations / 30).clamp(1, 1000),
            background: Vec3::ZERO,
            seed: 0,
            eval_every: 0,
            max_scale_growth: None,
            appearance: None,
            geometry_rate: None,
            backend: Default::default(),
            stop_when_flat: None,
        }
    }

    /// The density control this spec asks for, if any. The run's seed drives split sampling
    /// too, so one seed fixes the whole run.
    pub fn densify_config(&self) -> Option<DensifyConfig> {
        let seed = self.seed ^ 0x5eed_de75_1f1e_0000;
        match &self.densify {
            DensifyPolicy::Off => None,
            DensifyPolicy::Adaptive(config) => Some(DensifyConfig {
                seed,
                ..config.clone()
            }),
            DensifyPolicy::Budget { max } => Some(DensifyConfig {
                budget: Some(*max),
                ..densify_for_iterations(self.iterations, seed)
            }),
        }
    }
}

/// One training view in memory, at the training scale: camera, RGB target, optional label masks
/// (one per label channel, in `DamageClass::ALL` order) and an optional loss region.
#[derive(Clone, Debug)]
pub struct TrainView {
    pub name: String,
    pub camera: Camera,
    pub image: RgbImage,
    /// Per label channel a mask (absent class: an empty mask); empty when not supervised.
    pub labels: Vec<Mask>,
    /// Pixels outside the region (0) do not contribute to any loss.
    pub region: Option<Mask>,
    /// The light `image` was photographed in relative to the model's, when it is another
    /// survey's (`photo = M · colour + o`, fitted by `timeline::appearance`). The trainer fits
    /// `image` as it is, so a focused run maps such a photo into the model's light first
    /// (`to_model_light`): a later survey's light must not repaint the model. None: the model's
    /// own light.
    pub light: Option<ColourTransform>,
}

impl TrainView {
    /// Maps the photo into the model's light (undoing `light`, which is then None).
    pub fn to_model_light(&mut self) {
        if let Some(light) = self.light.take() {
            light.undo(&mut self.image);
        }
    }
}
