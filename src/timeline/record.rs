//! A survey's `metrics.json` as types: `TrainingRecord`, what a model trained from the survey's
//! own photos measured (written by `twin new` and the viewer's save alike, through
//! `record_training`), and `SurveyRecord`, any survey's file as read back (a training record, an
//! update's report, or something else). Old files keep reading: both spellings of the scale, and
//! keys this type does not know are skipped. No I/O beyond `Twin`'s.

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Deserializer, Serialize};

use crate::damage::TrainMode;
use crate::scene::ImageScale;
use crate::timeline::twin::HISTORY_FILE;
use crate::timeline::{TimelineError, Twin};
use crate::train::history::History;
use crate::train::run::TrainOutcome;

/// What a model trained from a survey's own photos measured. The fields are in alphabetical
/// order on purpose: the file was a `serde_json::json!` object before this type, whose keys are
/// written sorted, and `twin new` keeps writing them in that order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingRecord {
    pub gaussians: usize,
    /// Held-out PSNR (dB) and SSIM of the final model (None without held-out views).
    pub heldout_psnr: Option<f64>,
    pub heldout_ssim: Option<f64>,
    /// Steps trained.
    pub iterations: u32,
    /// Files from `twin new` before this type have none; it trained in the default mode.
    #[serde(default)]
    pub mode: TrainMode,
    /// The viewer wrote it as `resolution_factor`, a bare factor.
    #[serde(alias = "resolution_factor", deserialize_with = "scale_or_factor")]
    pub scale: ImageScale,
    /// Training wall time, pauses excluded.
    pub seconds: f64,
}

impl TrainingRecord {
    /// The record of `outcome`, a run in `mode` at `scale`.
    pub fn of(outcome: &TrainOutcome, mode: TrainMode, scale: ImageScale) -> TrainingRecord {
        TrainingRecord {
            gaussians: outcome.splats.len(),
            heldout_psnr: outcome.heldout.as_ref().map(|s| s.psnr),
            heldout_ssim: outcome.heldout.as_ref().map(|s| s.ssim),
            iterations: outcome.steps,
            mode,
            scale,
            seconds: outcome.seconds,
        }
    }
}

/// Records `outcome`, a model trained from survey `name`'s own photos in `mode` at `scale`, into
/// `twin`: the run's `history` where one was kept, then its `TrainingRecord` as the survey's
/// metrics (saved with the project by the next `Twin::save`). The model is the caller's to save:
/// the viewer saves the model on screen (edited since, maybe), `twin new` the trained one with
/// its damage tagged as the first survey's. Returns the metrics file.
pub fn record_training(
    twin: &mut Twin,
    name: &str,
    outcome: &TrainOutcome,
    mode: TrainMode,
    scale: ImageScale,
    history: Option<&History>,
) -> Result<PathBuf, TimelineError> {
    // A history of another training must not stay beside this record.
    match history {
        Some(history) => twin.save_history(name, history).map(drop)?,
        None => twin.replaces(name, HISTORY_FILE)?,
    }
    twin.save_metrics(name, &TrainingRecord::of(outcome, mode, scale))
}

/// A survey's `metrics.json` as read back. Any JSON reads: a file of neither shape is `Other`.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum SurveyRecord {
    /// The earlier twin updated with the survey's photos (`timeline::update::UpdateReport`).
    Updated(UpdateRecord),
    /// A model trained from the survey's own photos.
    Trained(TrainingRecord),
    Other(serde::de::IgnoredAny),
}

/// The part of an update's report (`UpdateReport`) read back: its wall time and the held-out
/// scores before and after.
#[derive(Clone, Debug, PartialEq, Deserialize)]
pub struct UpdateRecord {
    pub seconds: f64,
    pub refine: BeforeAfter,
}

#[derive(Clone, Debug, PartialEq, Deserialize)]
pub struct BeforeAfter {
    pub before: HeldoutScores,
    pub after: HeldoutScores,
}

/// Held-out scores as a refinement reports them (`damage::refine_quality::Quality`).
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
pub struct HeldoutScores {
    pub psnr: Option<f64>,
    /// IoU per damage class; a class whose IoU was not a number is written as null.
    #[serde(default)]
    pub iou: BTreeMap<String, Option<f64>>,
}

/// A scale as `ImageScale` writes it (`{"Factor": 4}`, `{"Width": 960}`) or a bare factor (the
/// viewer's `resolution_factor`).
fn scale_or_factor<'de, D: Deserializer<'de>>(deserializer: D) -> Result<ImageScale, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Spelling {
        Factor(u32),
        Scale(ImageScale),
    }
    Ok(match Spelling::deserialize(deserializer)? {
        Spelling::Factor(factor) => ImageScale::Factor(factor),
        Spelling::Scale(scale) => scale,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> SurveyRecord {
        serde_json::from_str(text).unwrap()
    }

    #[test]
    fn both_spellings_of_the_training_scale_read_and_unknown_keys_are_skipped() {
        let cli = r#"{"gaussians": 9, "heldout_psnr": 25.0, "heldout_ssim": null,
            "iterations": 3000, "scale": {"Factor": 4}, "seconds": 400.0}"#;
        let SurveyRecord::Trained(cli) = read(cli) else {
            panic!("a training record")
        };
        assert_eq!(
            (cli.scale, cli.mode),
            (ImageScale::Factor(4), TrainMode::Label)
        );
        assert_eq!((cli.heldout_psnr, cli.heldout_ssim), (Some(25.0), None));

        let viewer = r#"{"gaussians": 9, "heldout_psnr": null, "heldout_ssim": null,
            "iterations": 10, "mode": "rgb", "resolution_factor": 2, "seconds": 1.5,
            "added_later": [1, 2]}"#;
        let SurveyRecord::Trained(viewer) = read(viewer) else {
            panic!("a training record")
        };
        assert_eq!(
            (viewer.scale, viewer.mode),
            (ImageScale::Factor(2), TrainMode::Rgb)
        );

        let written = serde_json::to_string(&viewer).unwrap();
        assert!(written.contains(r#""scale":{"Factor":2}"#), "{written}");
        assert_eq!(read(&written), SurveyRecord::Trained(viewer));
    }

    #[test]
    fn an_update_report_and_files_of_other_shapes_read() {
        let update = r#"{"survey": "2025", "seconds": 70.0, "refine": {"strategy": "finetune",
            "before": {"iou": {"crack": 0.3, "rebar": null}, "psnr": 19.5, "recall": {}},
            "after": {"iou": {"crack": 0.5}, "psnr": null}}}"#;
        let SurveyRecord::Updated(update) = read(update) else {
            panic!("an update")
        };
        assert_eq!(update.refine.before.iou["rebar"], None);
        assert_eq!(update.refine.after.psnr, None);
        assert!(matches!(read(r#"{"psnr": 30.0}"#), SurveyRecord::Other(_)));
        assert!(matches!(read("[]"), SurveyRecord::Other(_)));
    }
}
