//! What made each survey's model, for the report's speed-against-accuracy chart: read from the
//! survey's `metrics.json` as `twin new` (a model trained from the survey's photos) and
//! `twin update` (the earlier twin refined with them) write it. An update gives two marks: the
//! earlier twin scored on this survey's held-out photos before it ran (at 0 s) and the updated
//! twin after it. A survey whose model came from elsewhere (`twin new --model`) has no marks.

use std::collections::BTreeMap;

use serde::Serialize;
use serde_json::Value;

use crate::report::tradeoff_chart::TradeoffPoint;

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
pub fn project_runs(survey: &str, metrics: &Value) -> Vec<ProjectRun> {
    let run = |step: &str, seconds: f64, scores: &Value, psnr_key: &str| ProjectRun {
        survey: survey.to_string(),
        step: step.to_string(),
        seconds,
        psnr: scores.get(psnr_key).and_then(Value::as_f64),
        iou: scores
            .get("iou")
            .and_then(Value::as_object)
            .map(|classes| {
                classes
                    .iter()
                    .filter_map(|(class, v)| Some((class.clone(), v.as_f64()?)))
                    .collect()
            })
            .unwrap_or_default(),
    };
    let Some(seconds) = metrics.get("seconds").and_then(Value::as_f64) else {
        return Vec::new();
    };
    match metrics.get("refine") {
        Some(refine) => match (refine.get("before"), refine.get("after")) {
            (Some(before), Some(after)) => vec![
                run("before update", 0.0, before, "psnr"),
                run("updated", seconds, after, "psnr"),
            ],
            _ => Vec::new(),
        },
        None => vec![run("trained", seconds, metrics, "heldout_psnr")],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_update_gives_two_marks_and_a_training_one() {
        let update = serde_json::json!({
            "seconds": 70.0,
            "refine": {
                "before": {"iou": {"crack": 0.3, "rebar": 0.2}, "psnr": 19.5},
                "after": {"iou": {"crack": 0.5, "rebar": 0.4}, "psnr": 20.1},
            }
        });
        let runs = project_runs("2025", &update);
        assert_eq!(runs.len(), 2);
        assert_eq!(
            (runs[0].step.as_str(), runs[0].seconds),
            ("before update", 0.0)
        );
        assert_eq!(runs[1].iou["crack"], 0.5);
        assert_eq!(runs[1].psnr, Some(20.1));
        assert_eq!(runs[1].point().label, "2025 updated");

        let trained = serde_json::json!({"seconds": 400.0, "heldout_psnr": 25.0, "gaussians": 9});
        let runs = project_runs("2024", &trained);
        assert_eq!(runs.len(), 1);
        assert_eq!((runs[0].psnr, runs[0].iou.len()), (Some(25.0), 0));
        assert!(project_runs("x", &serde_json::json!({"psnr": 30.0})).is_empty());
    }
}
