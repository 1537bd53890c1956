//! The mask-noise study's settings, rows and progress events: the types its runs, scoring,
//! fine-tune and chart share (they look down to this file; it uses none of them).

use serde::Serialize;

use crate::damage::setup::RunConfig;
use crate::damage::{DamageClass, TrainMode};

/// How the training masks are corrupted at a rate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NoiseModel {
    /// Every view, with an error of `rate ×` its damage area per class.
    #[default]
    Area,
    /// A fraction `rate` of the views, a few blobs each (`synth --mask-noise`).
    Views,
}

impl std::str::FromStr for NoiseModel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "area" => Ok(NoiseModel::Area),
            "views" => Ok(NoiseModel::Views),
            other => Err(format!("unknown noise model {other:?}: use area or views")),
        }
    }
}

/// Which twin a row scores: the coarse one trained on the corrupted masks, or that twin refined
/// at the photos' resolution on them (`fine`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StudyStage {
    #[default]
    Coarse,
    Finetune,
}

impl std::fmt::Display for StudyStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            StudyStage::Coarse => "coarse",
            StudyStage::Finetune => "finetune",
        })
    }
}

/// The study's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct StudyConfig {
    /// Error per view as a fraction of its damage area (`Area`), or the fraction of training
    /// views whose masks are corrupted (`Views`).
    pub rates: Vec<f32>,
    pub noise: NoiseModel,
    pub modes: Vec<TrainMode>,
    /// The run at every rate and mode (its `mode` is replaced by each of `modes`).
    pub run: RunConfig,
    /// Seed of the corruption (which views, which blobs).
    pub noise_seed: u64,
    pub threads: Option<usize>,
    /// Steps of the full-resolution fine-tune of each label-mode twin (0: none).
    pub fine_iterations: u32,
    /// The fraction of the fine-tune during which the label loss shapes the geometry (None: all
    /// of it; `Targets::label_geometry_steps`). Apart from the coarse run's
    /// (`run.label_geometry_until`): at full resolution the fine-tune's work is to reshape the
    /// damage's geometry to the masks.
    pub fine_label_geometry_until: Option<f32>,
    /// Weight of damage pixels in the fine-tune's label cross-entropy
    /// (`RefineConfig::label_pos_weight`).
    pub fine_label_pos_weight: f32,
}

/// One (mode, rate, class) result.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct StudyRow {
    pub mode: TrainMode,
    /// Rows written before the fine-tune stage existed are coarse.
    #[serde(default)]
    pub stage: StudyStage,
    pub rate: f32,
    pub class: DamageClass,
    /// IoU of the corrupted training masks against the clean ones.
    #[serde(deserialize_with = "nan_if_null")]
    pub input_iou: f64,
    /// IoU of the twin's rendered masks against the clean ones, on the training views.
    #[serde(deserialize_with = "nan_if_null")]
    pub twin_iou_train: f64,
    /// The same on held-out views.
    #[serde(deserialize_with = "nan_if_null")]
    pub twin_iou_heldout: f64,
    pub twin_f1_heldout: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub twin_precision_heldout: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub twin_recall_heldout: f64,
    /// IoU of the corrupted masks against the clean ones on the corrupted views only.
    #[serde(deserialize_with = "nan_if_null")]
    pub input_iou_noisy_views: f64,
    /// IoU of the twin against the clean masks on the same (corrupted) views.
    #[serde(deserialize_with = "nan_if_null")]
    pub twin_iou_noisy_views: f64,
    /// Pixels of the training views where the corrupted mask disagrees with the clean one.
    pub corrupted_pixels: u64,
    /// Of those, the fraction the twin renders as the clean mask has them (errors corrected).
    #[serde(deserialize_with = "nan_if_null", alias = "corrupted_pixels_corrected")]
    pub errors_corrected: f64,
    /// Errors corrected split by kind: of the damage pixels the corruption cut out, the fraction
    /// the twin renders as damage...
    #[serde(deserialize_with = "nan_if_null", default = "nan")]
    pub missed_corrected: f64,
    /// ...and of the pixels it added, the fraction the twin renders as no damage.
    #[serde(deserialize_with = "nan_if_null", default = "nan")]
    pub added_corrected: f64,
    /// Of the same corrupted pixels, the fraction the twin trained on the clean masks (rate 0, same
    /// mode and stage) renders as the clean mask has them: the most a twin at this resolution
    /// can be expected to correct (NaN when the study has no rate 0).
    #[serde(deserialize_with = "nan_if_null", default = "nan")]
    pub clean_twin_corrected: f64,
    /// Of the training-view pixels where the corrupted mask is right, the fraction the twin
    /// renders wrong (errors introduced; at rate 0, the clean-mask twin's own error).
    #[serde(deserialize_with = "nan_if_null", default = "nan")]
    pub errors_introduced: f64,
    /// Views whose masks were corrupted, of the training views.
    pub noisy_views: usize,
    #[serde(deserialize_with = "nan_if_null")]
    pub train_seconds: f64,
    pub gaussians: usize,
    pub heldout_psnr: Option<f64>,
}

fn nan() -> f64 {
    f64::NAN
}

/// JSON has no NaN (serde_json writes null): read null back as NaN.
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    use serde::Deserialize;
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Progress of the study, for a progress bar.
#[derive(Clone, Debug)]
pub enum StudyEvent {
    RunStarted {
        run: usize,
        runs: usize,
        mode: TrainMode,
        rate: f32,
    },
    Step {
        run: usize,
        step: u32,
        total: u32,
    },
    RunFinished {
        run: usize,
        rows: Vec<StudyRow>,
    },
    /// The full-resolution fine-tune of the label-mode twin at `rate` began.
    FineStarted {
        rate: f32,
    },
    /// It could not run (no damage Gaussians to refine, say): no fine-tune rows at `rate`.
    FineFailed {
        rate: f32,
        error: String,
    },
}
