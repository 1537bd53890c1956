//! The real-photo study's settings and results (the JSON written beside its chart).

use serde::{Deserialize, Serialize};

use crate::damage::evaluate::DamageScores;
use crate::metrics::MaskAgreement;

/// What the study runs.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RealStudyConfig {
    /// The twins train at 1/`scale` of the photos' size (the segmenter always runs at 1).
    pub scale: u32,
    /// Label-mode training steps (both twins).
    pub iterations: u32,
    /// Fine-tune steps at the photos' size (0: no refinement stage).
    pub fine_iterations: u32,
    /// The crack model's probability threshold.
    pub threshold: f32,
}

impl Default for RealStudyConfig {
    fn default() -> Self {
        RealStudyConfig {
            scale: 2,
            iterations: 1500,
            fine_iterations: 400,
            threshold: 0.5,
        }
    }
}

/// IoU, precision and recall of one class, pooled over views, with the truth's pixels.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ClassFigures {
    pub class: String,
    pub iou: f64,
    pub precision: f64,
    pub recall: f64,
    pub truth_pixels: u64,
}

impl ClassFigures {
    pub fn new(class: &str, agreement: &MaskAgreement) -> ClassFigures {
        ClassFigures {
            class: class.to_string(),
            iou: agreement.iou(),
            precision: agreement.precision(),
            recall: agreement.recall(),
            truth_pixels: agreement.true_positive + agreement.false_negative,
        }
    }

    /// Every class of `scores` with damage in its truth (an absent class scores a vacuous 1).
    pub fn of(scores: &DamageScores) -> Vec<ClassFigures> {
        scores
            .classes
            .iter()
            .filter(|(_, a)| a.true_positive + a.false_negative > 0)
            .map(|(class, a)| ClassFigures::new(class.id(), a))
            .collect()
    }
}

/// The crack model's mask of one photo against the stamped truth, at the photo's size.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewErrors {
    pub view: String,
    /// Truth and model crack pixels.
    pub truth_pixels: u64,
    pub marked_pixels: u64,
    pub iou: f64,
    pub precision: f64,
    pub recall: f64,
}

/// Pixels where a twin's input masks disagree with the truth and what the twin renders there.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Correction {
    /// Truth damage the input misses, and how many of them the twin renders as damage.
    pub missed: u64,
    pub missed_corrected: u64,
    /// Input damage that is not truth damage, and how many the twin renders as no damage.
    pub added: u64,
    pub added_corrected: u64,
    /// Pixels the input has right, and how many of them the twin renders wrong.
    pub right: u64,
    pub introduced: u64,
}

impl Correction {
    /// The share of the input's wrong pixels the twin renders right.
    pub fn corrected_share(&self) -> f64 {
        share(
            self.missed_corrected + self.added_corrected,
            self.missed + self.added,
        )
    }

    pub fn introduced_share(&self) -> f64 {
        share(self.introduced, self.right)
    }
}

fn share(part: u64, whole: u64) -> f64 {
    if whole == 0 {
        f64::NAN
    } else {
        part as f64 / whole as f64
    }
}

/// A label-mode twin's damage against the truth.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct TwinFigures {
    /// On the views it trained on and on the held-out ones, at its training scale.
    pub train: Vec<ClassFigures>,
    pub heldout: Vec<ClassFigures>,
    pub seconds: f64,
    pub gaussians: usize,
}

/// The twin trained on the crack model's masks: the model's masks and the twin's against the
/// truth at the training scale, and what the twin did with the model's errors.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct SegmentedTwin {
    pub model_train: ClassFigures,
    pub model_heldout: ClassFigures,
    pub twin: TwinFigures,
    pub correction: Correction,
    pub corrected_share: f64,
    pub introduced_share: f64,
}

/// The coarse twin and its fine-tune, both scored at the photos' size on the held-out views.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Refinement {
    pub coarse_heldout: Vec<ClassFigures>,
    pub refined_heldout: Vec<ClassFigures>,
    pub seconds: f64,
}

/// One truth total against the twin's measurement.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct QuantityRow {
    /// `crack length (m)`, `spalled area (m²)`, `rebar length (m)`.
    pub quantity: String,
    pub truth: f64,
    pub measured: f64,
    /// (measured − truth) / truth.
    pub relative_error: f64,
}

/// Everything the study measured.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RealStudy {
    pub config: RealStudyConfig,
    pub stamped: String,
    pub model: String,
    pub metres_per_unit: f64,
    pub views: usize,
    pub heldout_views: usize,
    /// Training size of the twins.
    pub width: u32,
    pub height: u32,
    /// §2: the crack model per photo at the photo's size, and pooled over all photos.
    pub segmenter_views: Vec<ViewErrors>,
    pub segmenter_pooled: ClassFigures,
    /// None when the masks were given, not made by the study.
    pub segmenter_seconds: Option<f64>,
    /// The twin on the stamped truth masks.
    pub truth_twin: TwinFigures,
    pub refinement: Option<Refinement>,
    /// Why there is no refinement when one was asked for (the refinement's refusal).
    #[serde(default)]
    pub refinement_skipped: Option<String>,
    pub segmented_twin: SegmentedTwin,
    /// Survey 2 against the survey-1 twin (refined when there is a refinement): new damage per
    /// class after the default cleaning, against `truth/new-damage`.
    pub change: Vec<ClassFigures>,
    /// Survey 1's twin (refined when there is a refinement) measured against the truth.
    pub quantities: Vec<QuantityRow>,
}
