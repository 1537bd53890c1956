//! `damage-twin train DATASET --out DIR`: starts a training job on a dataset and draws its
//! progress; writes `model.ply`, `metrics.json` and `curve.csv`. Training and evaluation happen
//! in the library (`damage::setup`, `damage::assess`); this file parses and writes.

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context;
use serde::Serialize;

use damage_twin::damage::TrainMode;
use damage_twin::damage::assess::{EvalRequest, ModelScores, evaluate_model};
use damage_twin::damage::evaluate::{DamageFigures, DamageReadout};
use damage_twin::damage::setup::{RunConfig, effective_mode, train_job};
use damage_twin::metrics::peak_rss_mb;
use damage_twin::scene::atomic::write_atomic;
use damage_twin::scene::run_folder::RunFolder;
use damage_twin::train::trainer::StageTimes;
use damage_twin::train::views::split_views;

use super::args::{JobArgs, RunArgs, drive, open_dataset, palette};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Dataset folder (COLMAP, transforms.json or NeRF-synthetic).
    pub dataset: PathBuf,
    /// Output folder for model.ply, metrics.json and curve.csv (and appearance.json with
    /// --appearance), replaced as a whole when the run ends.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, default_value_t = 7000)]
    pub iters: u32,
    #[command(flatten)]
    pub run: RunArgs,
    #[command(flatten)]
    pub job: JobArgs,
    /// Held-out PSNR is evaluated every this many steps for curve.csv (0: only at the end).
    #[arg(long, default_value_t = 500)]
    pub eval_every: u32,
    /// Cap on the Gaussian count (adaptive density control stops growing there).
    #[arg(long)]
    pub max_gaussians: Option<usize>,
    /// Most Gaussians the model ends with: density control grows to twice this, the least
    /// important (least blending weight over the training views) are pruned at 3/4 of the run,
    /// and training goes on. A count only (see `compact` for fractions).
    #[arg(long, value_parser = super::compact::parse_train_budget)]
    pub budget: Option<usize>,
    /// Learn each photo's exposure and white balance (a gain and offset per channel) with the
    /// model, so they are not baked into the Gaussians.
    #[arg(long)]
    pub appearance: bool,
    /// With --appearance: the first step that goes through the photos' light (before it the
    /// model is too rough for its error to be told from a photo's exposure).
    #[arg(long, default_value_t = 0)]
    pub appearance_from: u32,
    /// Damage supervision: rgb, overlay (masks painted into the photos) or label (per-Gaussian
    /// damage channels). Damage modes fall back to rgb on a dataset without masks.
    #[arg(long, default_value = "label")]
    pub mode: TrainMode,
    /// Weight of the label loss beside the photometric loss (label mode).
    #[arg(long, default_value_t = RunConfig::default().label_weight)]
    pub label_weight: f32,
    /// The fraction of the run during which the label loss shapes the geometry; after it only
    /// the label logits follow the masks (label mode; default: the whole run).
    #[arg(long, value_name = "FRACTION")]
    pub label_geometry_until: Option<f32>,
    /// Overlay mode's class colours. Without this flag they are chosen to contrast with the
    /// photos (and saved in model.ply); `quakecity` keeps DESIGN.md's colours, and class=r,g,b
    /// (repeatable, e.g. crack=0,0,255) overrides one of those.
    #[arg(long = "colour")]
    pub colours: Vec<String>,
    /// Weight of damage pixels in the label cross-entropy (label mode).
    #[arg(long, default_value_t = RunConfig::default().label_pos_weight)]
    pub label_pos_weight: f32,
    /// Learning rate of the label logits (label mode).
    #[arg(long, default_value_t = RunConfig::default().label_lr.unwrap_or(0.05))]
    pub label_lr: f32,
}

#[derive(Serialize)]
struct Metrics {
    psnr: Option<f64>,
    ssim: Option<f64>,
    train_psnr: Option<f64>,
    gaussians: usize,
    iterations: u32,
    seconds: f64,
    ms_per_iteration: f64,
    peak_rss_mb: Option<f64>,
    heldout_views: Vec<String>,
    train_views: usize,
    width: u32,
    height: u32,
    threads: usize,
    /// The SIMD build the CPU kernels ran (`DAMAGE_TWIN_SIMD` can lower it).
    simd: &'static str,
    rolled_back: u32,
    cancelled: bool,
    stage_ms_per_iteration: StageTimes,
    mode: TrainMode,
    /// Rendered damage against the reference masks on the held-out views.
    damage: Option<DamageFigures>,
    /// The same on the training views.
    damage_train: Option<DamageFigures>,
    damage_reference: Option<String>,
}

/// Writes `text` to `path` atomically.
fn write_text(path: &std::path::Path, text: &str) -> anyhow::Result<()> {
    write_atomic(path, |w| w.write_all(text.as_bytes()))
        .with_context(|| format!("writing {}", path.display()))
}

/// Every file a training run may write into its output folder: none of them is carried over
/// from an earlier run there (scene::run_folder), so an `appearance.json` of an `--appearance`
/// run does not stay beside a model trained without.
const TRAIN_OUTPUTS: &[&str] = &["model.ply", "curve.csv", "appearance.json", "metrics.json"];

pub fn run(args: Args) -> anyhow::Result<()> {
    let dataset = Arc::new(open_dataset(&args.dataset, args.run.images.background)?);
    let holdout = args.run.holdout.holdout();
    let (train_idx, test_idx) = split_views(&dataset, &holdout).map_err(anyhow::Error::msg)?;
    // The run's files are staged beside the output folder and swapped in whole at the end
    // (scene::run_folder): an unwritable place fails now, not after the run, and a kill at any
    // moment leaves the previous outputs or the new ones, never a mix.
    let outputs = RunFolder::begin(&args.out, TRAIN_OUTPUTS)
        .with_context(|| format!("preparing output folder {}", args.out.display()))?;

    let palette = palette(&args.colours)?;
    let config = RunConfig {
        mode: args.mode,
        palette,
        label_weight: args.label_weight,
        label_geometry_until: args.label_geometry_until,
        label_pos_weight: args.label_pos_weight,
        label_lr: Some(args.label_lr),
        eval_every: args.eval_every,
        max_gaussians: args.max_gaussians,
        budget: args.budget,
        contrasting_palette: args.colours.is_empty(),
        appearance: args
            .appearance
            .then(|| damage_twin::train::appearance::AppearanceConfig {
                start_step: args.appearance_from,
                ..Default::default()
            }),
        ..args.run.config(args.iters)
    };
    let mode = effective_mode(&dataset, args.mode);
    let threads = args.job.thread_count();
    let job = train_job(dataset.clone(), config, args.job.options());

    // The learning curve, kept in memory and written with the other outputs at the end, so a
    // failed or killed run never leaves an emptied curve.csv behind.
    let mut curve = String::from("step,seconds,loss,gaussians,heldout_psnr\n");
    let outcome = drive(job, "training", args.job.quiet, |p| {
        if p.psnr.is_some() || p.step % 10 == 0 || p.step == 1 {
            let psnr = p.psnr.map(|v| format!("{v:.3}")).unwrap_or_default();
            curve.push_str(&format!(
                "{},{:.3},{:.6},{},{}\n",
                p.step,
                p.elapsed.as_secs_f64(),
                p.loss,
                p.gaussians,
                psnr
            ));
        }
    })?;
    if let Some(scores) = &outcome.heldout {
        curve.push_str(&format!(
            "{},{:.3},,{},{:.3}\n",
            outcome.steps,
            outcome.seconds,
            outcome.splats.len(),
            scores.psnr
        ));
    }
    let peak_rss = peak_rss_mb();

    // Scores of the final model: image quality on the training views, damage on both sets. The
    // held-out PSNR is the job's (in overlay mode against the photos with damage painted on).
    let request = |indices: &[usize], photometric: bool| EvalRequest {
        indices: indices.to_vec(),
        scale: args.run.images.scale,
        background: args.run.images.background,
        sh_degree: args.run.sh_degree,
        photometric,
        half_appearance: false,
        readout: DamageReadout {
            mode,
            ..DamageReadout::for_model(&outcome.splats, palette)
        },
    };
    let train_scores = evaluate_model(
        &dataset,
        &outcome.splats,
        &request(&train_idx, true),
        &mut |_, _| {},
    )?;
    let heldout_scores: ModelScores = evaluate_model(
        &dataset,
        &outcome.splats,
        &request(&test_idx, false),
        &mut |_, _| {},
    )?;

    let (width, height) = args.run.images.scale.apply(
        dataset.views[train_idx[0]].camera.intrinsics.width,
        dataset.views[train_idx[0]].camera.intrinsics.height,
    );
    let steps = outcome.steps.max(1) as f64;
    let metrics = Metrics {
        psnr: outcome.heldout.as_ref().map(|s| s.psnr),
        ssim: outcome.heldout.as_ref().map(|s| s.ssim),
        train_psnr: train_scores.psnr,
        gaussians: outcome.splats.len(),
        iterations: outcome.steps,
        seconds: outcome.seconds,
        ms_per_iteration: outcome.seconds * 1000.0 / steps,
        peak_rss_mb: peak_rss,
        heldout_views: test_idx
            .iter()
            .map(|&i| dataset.views[i].name.clone())
            .collect(),
        train_views: train_idx.len(),
        width,
        height,
        threads,
        simd: damage_twin::simd::simd_level().name(),
        rolled_back: outcome.rolled_back,
        cancelled: outcome.cancelled,
        stage_ms_per_iteration: outcome.timings.per_step_ms(outcome.steps),
        mode,
        damage_reference: heldout_scores
            .damage_reference
            .clone()
            .or(train_scores.damage_reference.clone()),
        damage: heldout_scores.damage,
        damage_train: train_scores.damage,
    };

    // The model first, the metrics last: metrics.json always describes the model beside it.
    let model_path = args.out.join("model.ply");
    damage_twin::splats::ply::write_splats(&outputs.path("model.ply"), &outcome.splats)
        .with_context(|| format!("writing {}", model_path.display()))?;
    write_text(&outputs.path("curve.csv"), &curve)?;
    if !outcome.appearance.is_empty() {
        // Each training photo's learnt light: photo ≈ gain ⊙ render + offset.
        let lights: Vec<_> = train_idx
            .iter()
            .zip(&outcome.appearance)
            .map(|(&i, light)| {
                serde_json::json!({
                    "view": dataset.views[i].name,
                    "gain": [light.matrix[0][0], light.matrix[1][1], light.matrix[2][2]],
                    "offset": light.offset,
                })
            })
            .collect();
        write_text(
            &outputs.path("appearance.json"),
            &serde_json::to_string_pretty(&lights)?,
        )?;
    }
    let json = serde_json::to_string_pretty(&metrics)?;
    write_text(&outputs.path("metrics.json"), &json)?;
    outputs
        .commit()
        .with_context(|| format!("replacing {}", args.out.display()))?;
    println!("{json}");
    Ok(())
}
