//! What made each survey's model, for the report's speed-against-accuracy chart: read from the
//! survey's `metrics.json` as `twin new` (a model trained from the survey's photos) and
//! `twin update` (the earlier twin refined with them) write it. An update gives two marks: the
//! earlier twin scored on this survey's held-out photos before it ran (at 0 s) and the updated
//! twin after it. A survey whose model came from elsewhere (`twin new --model`) has no marks.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::report::tradeoff_chart::TradeoffPoint;
use crate::timeline::record::{HeldoutScores, SurveyRecord};

/// One mark: a survey's model at one step, its wall time and held-out scores on that survey's
/// photos.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ProjectRun {
    pub survey: String,
    /// `trained`, `before update` or `updated`.
    pub step: String,
    /// Wall time of the step (0 for `before update`).
    pub seconds: f64,
    /// Held-out PSNR (dB), where measured.
    pub psnr: Option<f64>,
    /// Held-out IoU per damage class, where measured.
    pub iou: BTreeMap<String, f64>,
}

impl ProjectRun {
    pub fn point(&self) -> TradeoffPoint {
        TradeoffPoint {
            label: format!("{} {}", self.survey, self.step),
            seconds: self.seconds,
            iou: self.iou.clone(),
            psnr: self.psnr.unwrap_or(f64::NAN),
        }
    }
}

/// The marks `metrics` (survey `survey`'s `metrics.json`) holds; none for metrics of another
/// shape.
pub fn project_runs(survey: &str, metrics: &SurveyRecord) -> Vec<ProjectRun> {
    let run = |step: &str, seconds: f64, psnr: Option<f64>, iou: &BTreeMap<String, Option<f64>>| {
        ProjectRun {
            survey: survey.to_string(),
            step: step.to_string(),
            seconds,
            psnr,
            iou: iou
                .iter()
                .filter_map(|(class, v)| Some((class.clone(), (*v)?)))
                .collect(),
        }
    };
    let scored = |step: &str, seconds: f64, scores: &HeldoutScores| {
        run(step, seconds, scores.psnr, &scores.iou)
    };
    match metrics {
        SurveyRecord::Updated(update) => vec![
            scored("before update", 0.0, &update.refine.before),
            scored("updated", update.seconds, &update.refine.after),
        ],
        SurveyRecord::Trained(trained) => {
            vec![run(
                "trained",
                trained.seconds,
                trained.heldout_psnr,
                &BTreeMap::new(),
            )]
        }
        SurveyRecord::Other(_) => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_update_gives_two_marks_and_a_training_one() {
        let read =
            |value: serde_json::Value| serde_json::from_value::<SurveyRecord>(value).unwrap();
        let update = read(serde_json::json!({
            "seconds": 70.0,
            "refine": {
                "before": {"iou": {"crack": 0.3, "rebar": 0.2}, "psnr": 19.5},
                "after": {"iou": {"crack": 0.5, "rebar": 0.4}, "psnr": 20.1},
            }
        }));
        let runs = project_runs("2025", &update);
        assert_eq!(runs.len(), 2);
        assert_eq!(
            (runs[0].step.as_str(), runs[0].seconds),
            ("before update", 0.0)
        );
        assert_eq!(runs[1].iou["crack"], 0.5);
        assert_eq!(runs[1].psnr, Some(20.1));
        assert_eq!(runs[1].point().label, "2025 updated");

        let trained = read(serde_json::json!({
            "seconds": 400.0, "heldout_psnr": 25.0, "heldout_ssim": 0.8, "gaussians": 9,
            "iterations": 3000, "scale": {"Factor": 4},
        }));
        let runs = project_runs("2024", &trained);
        assert_eq!(runs.len(), 1);
        assert_eq!((runs[0].psnr, runs[0].iou.len()), (Some(25.0), 0));
        assert!(project_runs("x", &read(serde_json::json!({"psnr": 30.0}))).is_empty());
    }
}
