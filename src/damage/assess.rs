//! How good a model is on a dataset's views: per-view PSNR and SSIM against the photos, and the
//! rendered damage against the reference masks (a synthetic survey's clean `truth/`, else the
//! dataset's masks). The one evaluation that `train`, `eval`, the headless demo and the viewer
//! call, directly or as a job.

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::Vec3;
use serde::Serialize;

use crate::damage::TrainMode;
use crate::damage::evaluate::{DamageFigures, DamageReadout};
use crate::damage::reference::{load_reference_views, reference_source};
use crate::damage::view_damage::{ViewDamage, evaluate_damage_by_view};
use crate::raster::{Rasterizer, RenderOutput, RenderSettings};
use crate::scene::{Dataset, ImageScale, SceneError};
use crate::splats::Splats;
use crate::train::evaluate::{half_lit_psnr, view_quality};
use crate::train::job::{Job, JobContext, JobError, JobOptions, Progress};
use crate::train::views::load_views;

/// What to evaluate a model on, and how.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalRequest {
    /// Indices of the views in `dataset.views`.
    pub indices: Vec<usize>,
    pub scale: ImageScale,
    pub background: Vec3,
    /// Highest SH degree rendered (the model's own when higher).
    pub sh_degree: u32,
    /// Score the photos (PSNR, SSIM); off when only damage is wanted.
    pub photometric: bool,
    /// With `photometric`, also score each photo's right half after fitting its light to the
    /// render on its left half (`train::evaluate::half_lit_psnr`, the NeRF-W protocol for a
    /// model whose training photos differ in exposure).
    pub half_appearance: bool,
    /// How rendered damage is read; RGB mode scores no damage.
    pub readout: DamageReadout,
}

/// One view's image quality.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewScore {
    pub name: String,
    pub psnr: f64,
    pub ssim: f64,
}

/// A model's scores on the requested views.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ModelScores {
    /// Means over `views` (None when photos were not scored or no view was given).
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    pub views: Vec<ViewScore>,
    /// `half_appearance`: the mean PSNR of the views' right halves, light fitted on the left.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub psnr_half_appearance: Option<f64>,
    /// Rendered damage against the reference masks (None without masks, or in RGB mode).
    pub damage: Option<DamageFigures>,
    /// Each view's damage alone, with the ground sample distance at its damage (empty without
    /// masks).
    pub damage_views: Vec<ViewDamage>,
    /// The folder the reference masks came from.
    pub damage_reference: Option<String>,
}

/// Scores `splats` on the requested views of `dataset`; `on_view(done, total)` after each view.
pub fn evaluate_model(
    dataset: &Dataset,
    splats: &Splats,
    request: &EvalRequest,
    on_view: &mut dyn FnMut(usize, usize),
) -> Result<ModelScores, SceneError> {
    let mut scores = ModelScores::default();
    let total = request.indices.len();
    if request.photometric && !request.indices.is_empty() {
        let views = load_views(dataset, &request.indices, request.scale, false)?;
        let settings =
            RenderSettings::new(request.background, request.sh_degree.min(splats.sh_degree));
        let mut rasterizer = Rasterizer::new();
        let mut out = RenderOutput::default();
        let mut half_total = 0.0;
        for (done, view) in views.iter().enumerate() {
            rasterizer.forward(splats, &view.camera, &settings, &mut out);
            if request.half_appearance {
                half_total += half_lit_psnr(&out.color, view);
            }
            // Ignored pixels (the view's ignore mask) are not scored.
            let (psnr, ssim) = view_quality(&out.color, view);
            scores.views.push(ViewScore {
                name: view.name.clone(),
                psnr,
                ssim,
            });
            on_view(done + 1, total);
        }
        let n = scores.views.len() as f64;
        scores.psnr = Some(scores.views.iter().map(|v| v.psnr).sum::<f64>() / n);
        scores.ssim = Some(scores.views.iter().map(|v| v.ssim).sum::<f64>() / n);
        scores.psnr_half_appearance = request.half_appearance.then(|| half_total / n);
    }
    if request.readout.mode != TrainMode::Rgb
        && !request.indices.is_empty()
        && let Some(source) = reference_source(dataset)
    {
        let views = load_reference_views(dataset, &source, &request.indices, request.scale)?;
        let (damage, per_view) =
            evaluate_damage_by_view(splats, &views, &request.readout, request.background);
        scores.damage = Some(damage.figures());
        scores.damage_views = per_view;
        scores.damage_reference = Some(source.masks().describe());
    }
    Ok(scores)
}

/// `evaluate_model` as a job, with a progress report per view.
pub fn evaluate_job(
    dataset: Arc<Dataset>,
    splats: Arc<Splats>,
    request: EvalRequest,
    options: JobOptions,
) -> Job<ModelScores> {
    Job::spawn("evaluate", options, move |ctx: &mut JobContext| {
        if request.indices.is_empty() {
            return Err(JobError::Invalid(format!(
                "{}: no views to evaluate under this held-out rule",
                dataset.root.display()
            )));
        }
        let started = Instant::now();
        let gaussians = splats.len();
        let mut report = |done: usize, total: usize| {
            let elapsed = started.elapsed();
            let per_view = elapsed.as_secs_f64() / done.max(1) as f64;
            ctx.progress(Progress {
                phase: "evaluate",
                step: done as u32,
                total: total as u32,
                loss: f32::NAN,
                psnr: None,
                gaussians,
                elapsed,
                eta: Duration::from_secs_f64(per_view * total.saturating_sub(done) as f64),
            });
        };
        Ok(evaluate_model(&dataset, &splats, &request, &mut report)?)
    })
}
