//! What a refinement is steered by (`RefineConfig`): the leaf the refinement's files
//! (`refine`, `refine_selection`, `refine_quality`) all look down to.

use glam::Vec3;

use crate::damage::select::SelectConfig;
use crate::scene::ImageScale;
use crate::train::focus::Strategy;
use crate::train::focus::hulls::HullConfig;
use crate::train::spec::LrOverrides;
use crate::train::views::Holdout;

/// Everything a refinement is steered by.
#[derive(Clone, Debug, PartialEq)]
pub struct RefineConfig {
    pub select: SelectConfig,
    pub hulls: HullConfig,
    pub strategy: Strategy,
    /// The high resolution the selection is refined at.
    pub scale: ImageScale,
    /// The resolution of the masks the selection is validated against.
    pub select_scale: ImageScale,
    pub iterations: u32,
    /// Held-out views: never trained on, scored before and after.
    pub holdout: Holdout,
    pub background: Vec3,
    pub seed: u64,
    /// Pixels of context kept around each hull's box in its crop.
    pub crop_margin_px: u32,
    /// Regions join selected Gaussians within this many median neighbour spacings.
    pub region_spacings: f32,
    /// Weight of the label loss and of damage pixels in it (label mode).
    pub label_weight: f32,
    pub label_pos_weight: f32,
    /// The fraction of the refinement during which the label loss shapes the geometry
    /// (`Targets::label_geometry_steps`; None: all of it).
    pub label_geometry_until: Option<f32>,
    /// The label logits' rate (None: the strategy's, `RefineConfig::rates`).
    pub label_lr: Option<f32>,
    /// Refine these Gaussians (a person's selection) instead of selecting damage by the masks.
    pub given: Option<Vec<u32>>,
    /// Learning rates other than the strategy's (the label rate is `label_lr`; see
    /// `RefineConfig::rates`).
    pub lr: LrOverrides,
    /// Each refined Gaussian's scale stays within this factor of its size before (None: free).
    pub max_scale_growth: Option<f32>,
    /// A factor on the position, scale, rotation and opacity rates of the selected Gaussians that
    /// are only neighbours of damage (None: full rates; `TrainSpec::geometry_rate`).
    pub neighbour_geometry_rate: Option<f32>,
    /// The renderer the refinement trains on.
    pub backend: crate::train::backend_choice::Backend,
    /// Stop before `iterations` once the hull loss stops improving (None: run them all).
    pub stop_when_flat: Option<crate::train::plateau::Plateau>,
    /// A study's oracle: hulls from the dataset's truth masks instead of from the selection
    /// (`truth_hulls`; refused without truth masks).
    pub hulls_from_truth: bool,
    /// Timed rounds (one step per view of the refinement's and of full-image steps each) of
    /// the cost comparison `RefineReport::step_costs`; 0 (the default) skips it, as every
    /// refinement and survey update does: `bench --refine` asks for it.
    pub cost_rounds: u32,
}

impl Default for RefineConfig {
    fn default() -> Self {
        let run = crate::damage::setup::RunConfig::default();
        RefineConfig {
            select: SelectConfig::default(),
            hulls: HullConfig::default(),
            strategy: Strategy::Finetune,
            scale: ImageScale::Factor(1),
            select_scale: ImageScale::Factor(4),
            iterations: 1000,
            holdout: Holdout::Auto { every: 8 },
            background: Vec3::ZERO,
            seed: 0,
            crop_margin_px: 8,
            region_spacings: 6.0,
            label_weight: run.label_weight,
            // Measured on the demo building (docs/DAMAGE.md, retrain 1000 steps at 960×540):
            // the coarse run's 4 leaves cracks too wide at full resolution (precision 0.72 against
            // recall 0.95, IoU 0.69); 2 balances them (0.80 / 0.89, IoU 0.73) and 1 loses rebar
            // recall (0.53).
            label_pos_weight: 2.0,
            label_geometry_until: run.label_geometry_until,
            label_lr: None,
            given: None,
            lr: LrOverrides::default(),
            max_scale_growth: None,
            neighbour_geometry_rate: None,
            backend: Default::default(),
            stop_when_flat: None,
            hulls_from_truth: false,
            cost_rounds: 0,
        }
    }
}

/// A fine-tune's rate of the damage label logits, where the config sets none: four times a
/// from-scratch label run's 0.05. A fine-tune continues a trained twin for a few hundred steps;
/// its labels need to sharpen at the full resolution, not be learnt. Measured on the demo
/// building (docs/TIMELINE.md, "Fine-tune rates", coarse twin 3000 steps at 240×135,
/// fine-tune at 960×540, held-out IoU): 300 steps at 0.2 gave crack / rebar 0.686 / 0.445
/// against 0.680 / 0.386 at 0.05.
pub const FINETUNE_LABEL_RATE: f32 = 0.2;

/// A fine-tune's log-scale rate, where the config sets none: twice the from-scratch 5e-3, so
/// the crack Gaussians narrow to the full resolution's pixel within the run (300 steps: crack
/// 0.688 against 0.680; with the label rate above 0.690 / 0.461, where 500 steps at the
/// from-scratch rates reach 0.701 / 0.466). The update shrinks faster still
/// (`timeline::update_rates`), but its position rate, held constant, breaks a fine-tune's cracks
/// at 960×540 (0.454 at 300 steps).
pub const FINETUNE_SCALE_RATE: f32 = 1e-2;

impl RefineConfig {
    /// The rates the refinement trains at: the config's where it sets them, else its
    /// strategy's. A fine-tune takes `FINETUNE_LABEL_RATE` and `FINETUNE_SCALE_RATE`; a retrain,
    /// which grows its Gaussians again by density control, the from-scratch ones
    /// (`RunConfig::label_lr`).
    pub fn rates(&self) -> LrOverrides {
        let mut lr = self.lr;
        let (label, log_scales) = match self.strategy {
            Strategy::Finetune => (Some(FINETUNE_LABEL_RATE), Some(FINETUNE_SCALE_RATE)),
            Strategy::Retrain => (crate::damage::setup::RunConfig::default().label_lr, None),
        };
        lr.raw_labels = self.label_lr.or(self.lr.raw_labels).or(label);
        lr.log_scales = self.lr.log_scales.or(log_scales);
        lr
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_finetune_takes_its_own_rates_unless_the_config_sets_them() {
        let finetune = RefineConfig::default().rates();
        assert_eq!(finetune.raw_labels, Some(FINETUNE_LABEL_RATE));
        assert_eq!(finetune.log_scales, Some(FINETUNE_SCALE_RATE));
        // Everything else stays as from scratch.
        let rest = LrOverrides {
            raw_labels: None,
            log_scales: None,
            ..finetune
        };
        assert_eq!(rest, LrOverrides::default());

        let retrain = RefineConfig {
            strategy: Strategy::Retrain,
            ..RefineConfig::default()
        }
        .rates();
        let run = crate::damage::setup::RunConfig::default();
        assert_eq!(retrain.raw_labels, run.label_lr);
        assert_eq!(retrain.log_scales, None);

        // A config's own rates win (the survey update sets both).
        let set = RefineConfig {
            label_lr: Some(0.3),
            lr: LrOverrides {
                log_scales: Some(4e-2),
                ..LrOverrides::default()
            },
            ..RefineConfig::default()
        }
        .rates();
        assert_eq!(set.raw_labels, Some(0.3));
        assert_eq!(set.log_scales, Some(4e-2));
    }
}
