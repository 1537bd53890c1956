//! The Gaussian-budget study (issue 24 §4) on one scene, as a job: a full run, `train --budget`
//! at fractions of the full run's final count, and compaction of the full model
//! (`damage::compact`) to fractions of it, each scored by held-out PSNR, Gaussians, bytes as PLY
//! and seconds. The models are written as PLY, since their size is one of the figures.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::damage::compact::{CompactConfig, heldout_psnr, prepare_compaction};
use crate::damage::setup::{RunConfig, prepare_run};
use crate::scene::{Dataset, SceneError};
use crate::splats::Splats;
use crate::studies::budget::rows::BudgetRow;
use crate::train::compact::run_compaction;
use crate::train::job::{Job, JobContext, JobError, JobOptions};
use crate::train::run::run_training;
use crate::train::views::split_views;

/// The study's settings on one scene.
#[derive(Clone, Debug, PartialEq)]
pub struct BudgetConfig {
    /// The scene's name in the rows (`demo`, `lego`).
    pub scene: String,
    /// The full run; the budgeted runs are the same with a budget, and compaction fine-tunes at
    /// its scale, background, held-out rule and seed.
    pub run: RunConfig,
    /// Budgeted runs, as fractions of the full run's final count.
    pub budgets: Vec<f64>,
    /// Compactions of the full model, as fractions of its count.
    pub compact: Vec<f64>,
    /// Fine-tuning steps of each compaction.
    pub compact_iterations: u32,
    /// Where the models are written (`<scene>-<method>.ply`).
    pub models_dir: PathBuf,
}

/// What the study measured on its scene.
#[derive(Clone, Debug)]
pub struct BudgetOutcome {
    pub rows: Vec<BudgetRow>,
    /// The training views' size at the run's scale.
    pub size: (u32, u32),
}

/// Runs the study as a job.
pub fn budget_job(
    dataset: Arc<Dataset>,
    config: BudgetConfig,
    options: JobOptions,
) -> Job<BudgetOutcome> {
    Job::spawn("budget", options, move |ctx| {
        run_budget(ctx, &dataset, &config)
    })
}

fn percent(fraction: f64) -> String {
    format!("{:.0}%", fraction * 100.0)
}

/// Writes `splats` to DIR/NAME.ply (NAME made a file name) and returns its size.
fn save(dir: &Path, name: &str, splats: &Splats) -> Result<u64, SceneError> {
    let file: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    let path = dir.join(format!("{file}.ply"));
    crate::splats::ply::write_splats(&path, splats)?;
    std::fs::metadata(&path)
        .map(|m| m.len())
        .map_err(|e| SceneError::io(&path, e))
}

/// The whole study in the calling job; `ctx` logs each model as it starts and its row.
pub fn run_budget(
    ctx: &mut JobContext,
    dataset: &Dataset,
    config: &BudgetConfig,
) -> Result<BudgetOutcome, JobError> {
    let base = &config.run;
    let (train_idx, test_idx) = split_views(dataset, &base.holdout).map_err(JobError::Invalid)?;
    let first = &dataset.views[train_idx[0]].camera.intrinsics;
    let size = base.scale.apply(first.width, first.height);
    let psnr =
        |splats: &Splats| heldout_psnr(dataset, splats, &test_idx, base.scale, base.background);
    let scene = &config.scene;
    let mut rows = Vec::new();
    let mut row = |ctx: &mut JobContext, method: String, splats: &Splats, seconds: f64| {
        let name = format!("{scene}-{method}");
        let row = BudgetRow {
            scene: scene.clone(),
            psnr: psnr(splats)?,
            gaussians: splats.len(),
            bytes: save(&config.models_dir, &name, splats)?,
            seconds,
            method,
        };
        ctx.log(format!("  {row:?}"));
        rows.push(row.clone());
        Ok::<BudgetRow, JobError>(row)
    };
    let train = |ctx: &mut JobContext, budget: Option<usize>| {
        let run = prepare_run(
            dataset,
            &RunConfig {
                budget,
                ..base.clone()
            },
        )?;
        for note in run.notes {
            ctx.log(note);
        }
        run_training(ctx, run.setup, "train")
    };

    ctx.log(format!("{scene}: full"));
    let full = train(ctx, None)?;
    let full_row = row(ctx, "full".into(), &full.splats, full.seconds)?;
    for &fraction in &config.budgets {
        let method = format!("budget {}", percent(fraction));
        ctx.log(format!("{scene}: {method}"));
        let budget = (full.splats.len() as f64 * fraction).round().max(1.0) as usize;
        let outcome = train(ctx, Some(budget))?;
        row(ctx, method, &outcome.splats, outcome.seconds)?;
    }
    for &fraction in &config.compact {
        let method = format!("compact {}", percent(fraction));
        ctx.log(format!("{scene}: {method}"));
        let compact = CompactConfig {
            keep: (full.splats.len() as f64 * fraction).round().max(1.0) as usize,
            iterations: config.compact_iterations,
            scale: base.scale,
            holdout: base.holdout.clone(),
            background: base.background,
            seed: base.seed,
            keep_pruned: false,
        };
        let setup = prepare_compaction(dataset, (*full.splats).clone(), &compact)?;
        let compacted = run_compaction(ctx, setup)?;
        row(
            ctx,
            method,
            &compacted.splats,
            full_row.seconds + compacted.seconds,
        )?;
    }
    Ok(BudgetOutcome { rows, size })
}
