//! The training benchmark: a run prepared exactly as `train` prepares it (`setup::prepare_run`,
//! photos only), timed per stage, with its memory and bytes per Gaussian. What `bench` prints.

use std::sync::Arc;

use serde::Serialize;

use crate::damage::TrainMode;
use crate::damage::setup::{RunConfig, prepare_run};
use crate::gpu::{GpuBackend, GpuContext};
use crate::metrics::peak_rss_mb;
use crate::raster::{PixelGrads, RasterBackend, RenderOutput, RenderSettings};
use crate::scene::Dataset;
use crate::splats::Splats;
use crate::train::job::{Job, JobError, JobOptions};
use crate::train::run::run_training;
use crate::train::trainer::StageTimes;

/// What `bench` reports.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    pub dataset: String,
    pub width: u32,
    pub height: u32,
    pub train_views: usize,
    pub iterations: u32,
    /// The renderer that trained (`--backend`): for the GPU, `stage_ms_per_iteration` reads
    /// `project` as the model's upload, `rasterize` as the forward kernels and the frame's
    /// read-back, `rasterize_backward` as the pixel gradients' upload and that kernel,
    /// `project_backward` as that kernel and the gradients' read-back.
    pub renderer: String,
    pub threads: usize,
    /// The SIMD build the CPU kernels ran (`DAMAGE_TWIN_SIMD` can lower it).
    pub simd: &'static str,
    /// Time spent in training steps (held-out evaluation excluded).
    pub seconds: f64,
    pub ms_per_iteration: f64,
    pub stage_ms_per_iteration: StageTimes,
    pub initial_gaussians: usize,
    pub gaussians: usize,
    pub peak_rss_mb: Option<f64>,
    /// Parameters only (what a saved model holds in memory).
    pub model_bytes_per_gaussian: usize,
    /// Parameters + gradients + Adam moments + density statistics.
    pub training_bytes_per_gaussian: usize,
    pub heldout_psnr: Option<f64>,
    /// On the GPU backend: one GPU-resident step (what `--backend gpu` trains with) of the
    /// final model on the first training view, timed per kernel.
    pub gpu_step_ms: Option<crate::gpu::StepProfile>,
    /// The same step on the per-step path (model up, frame down, gradients down), timed per
    /// kernel and per transfer.
    pub gpu_per_step_path_ms: Option<crate::gpu::StepProfile>,
}

/// f32 values per Gaussian of the parameters.
fn floats_per_gaussian(splats: &Splats) -> usize {
    3 + 3 + 4 + 1 + splats.sh_coeffs() * 3 + splats.label_channels
}

/// One GPU step of `splats` on `view` timed per stage, resident (the photometric loss on the
/// GPU) and on the per-step path (with the L1 loss's pixel gradients).
fn profile_gpu_step(
    splats: &Splats,
    view: &crate::train::spec::TrainView,
    settings: &RenderSettings,
) -> Result<(crate::gpu::StepProfile, crate::gpu::StepProfile), crate::gpu::GpuError> {
    let ctx = GpuContext::new()?;
    let mut backend = GpuBackend::new(&ctx)?;
    let targets = crate::train::spec::Targets::default();
    let params = crate::train::label_loss::LabelLossParams::default();
    let no_labels: Vec<Option<&[u8]>> = vec![None; splats.label_channels];
    let resident = backend.profile_resident_step(
        splats,
        &view.camera,
        settings,
        &crate::gpu::loss::LossTarget {
            photo: &view.image.data,
            region: None,
            labels: &no_labels,
        },
        &crate::gpu::loss::LossWeights {
            ssim_lambda: targets.ssim_lambda,
            rgb_weight: 1.0,
            label_weight: 0.0,
            pos_weight: params.pos_weight,
            eps: params.eps,
            window: crate::train::ssim::gaussian_window(),
        },
    )?;
    let mut backend = GpuBackend::new(&ctx)?;
    let mut out = RenderOutput::default();
    backend.forward(splats, &view.camera, settings, &mut out);
    let n = out.color.len().max(1) as f32;
    let v_color: Vec<f32> = out
        .color
        .iter()
        .zip(&view.image.data)
        .map(|(r, p)| (r - p).signum() / n)
        .collect();
    let v_out = PixelGrads {
        color: &v_color,
        alpha: None,
        depth: None,
        labels: None,
    };
    Ok((
        resident,
        backend.profile_step(splats, &view.camera, settings, &v_out)?,
    ))
}

/// Benchmarks `config` (run in RGB mode: the benchmark times the photometric engine) on
/// `dataset`: the training job, then its stage times.
pub fn bench_job(
    dataset: Arc<Dataset>,
    config: RunConfig,
    options: JobOptions,
) -> Job<BenchReport> {
    Job::spawn("bench", options, move |ctx| {
        let config = RunConfig {
            mode: TrainMode::Rgb,
            eval_every: 0,
            ..config
        };
        let run = prepare_run(&dataset, &config)?;
        for note in run.notes {
            ctx.log(note);
        }
        let first = run
            .setup
            .views
            .first()
            .ok_or_else(|| JobError::Invalid("no training views".into()))?;
        let (width, height) = (first.image.width, first.image.height);
        let train_views = run.setup.views.len();
        let initial_gaussians = run.setup.splats.len();
        let profile_view = first.clone();
        let settings = RenderSettings::new(config.background, config.sh_degree);
        // The run itself, exactly as a training job runs it, in this job's thread pool.
        let outcome = run_training(ctx, run.setup, "train")?;
        let steps = outcome.steps;
        let seconds = outcome.timings.total;
        let floats = floats_per_gaussian(&outcome.splats);
        let (gpu_step_ms, gpu_per_step_path_ms) = if outcome.renderer.starts_with("GPU") {
            let (resident, per_step) = profile_gpu_step(&outcome.splats, &profile_view, &settings)
                .map_err(|e| JobError::Other(Box::new(e)))?;
            (Some(resident), Some(per_step))
        } else {
            (None, None)
        };
        Ok(BenchReport {
            dataset: dataset.root.display().to_string(),
            width,
            height,
            train_views,
            iterations: steps,
            renderer: outcome.renderer.clone(),
            threads: rayon::current_num_threads(),
            simd: crate::simd::simd_level().name(),
            seconds,
            ms_per_iteration: seconds * 1000.0 / steps.max(1) as f64,
            stage_ms_per_iteration: outcome.timings.per_step_ms(steps),
            initial_gaussians,
            gaussians: outcome.splats.len(),
            peak_rss_mb: peak_rss_mb(),
            model_bytes_per_gaussian: floats * 4 + 8 + 2 + 1,
            // params + grads + 2 Adam moments, metadata, visibility, 2D-gradient norm, radius,
            // and the densifier's three statistics.
            training_bytes_per_gaussian: floats * 4 * 4 + 11 + 1 + 4 + 4 + 12,
            heldout_psnr: outcome.heldout.map(|s| s.psnr),
            gpu_step_ms,
            gpu_per_step_path_ms,
        })
    })
}
