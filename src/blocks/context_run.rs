//! The context job: one short whole run at a low resolution over every training photo of a plan
//! (CityGaussian's coarse prior), trained once before the blocks. Each block renders its
//! Gaussians outside the block's box frozen behind its own (`block_run`), and the merge keeps
//! those outside every block's box (`merge`): the sky and the far ground, which no block owns.
//! Its result is a run folder like a block's (`PLAN/context/result/`: `model.ply`,
//! `context.json`), atomic and idempotent the same way.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::blocks::block_run::{commit_model, committed_record, load_photos, run_config};
use crate::blocks::plan::Plan;
use crate::damage::setup::model_and_spec;
use crate::scene::run_folder::RunFolder;
use crate::scene::{Dataset, SceneError};
use crate::splats::Splats;
use crate::train::focus::{Focus, ViewLights};
use crate::train::job::{JobContext, JobError};
use crate::train::run::{TrainSetup, run_training};
use crate::train::views::{Holdout, split_views};

/// The files the context's result folder holds.
pub const CONTEXT_OUTPUTS: &[&str] = &["model.ply", "context.json"];

/// The run folder the context is committed to.
pub fn context_folder(plan_dir: &Path) -> PathBuf {
    plan_dir.join("context").join("result")
}

/// The context's model in a plan folder.
pub fn context_model_path(plan_dir: &Path) -> PathBuf {
    context_folder(plan_dir).join("model.ply")
}

/// What the context run records beside its model (`context.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContextRecord {
    /// The digest of the plan it was trained for (`Plan::digest`).
    pub plan_digest: String,
    pub photos: usize,
    pub steps: u32,
    pub scale: String,
    pub gaussians: usize,
    pub seconds: f64,
    /// Peak resident memory of the process that trained it (None where not measured).
    pub peak_rss_mb: Option<f64>,
}

/// The record of the context when it is finished for this plan (its model beside it).
pub fn context_finished(plan_dir: &Path, plan: &Plan) -> Option<ContextRecord> {
    let record: ContextRecord = committed_record(&context_folder(plan_dir), "context.json")?;
    (record.plan_digest == plan.digest()).then_some(record)
}

/// The finished context's Gaussians; a plan with a context whose job has not finished is a
/// one-line error saying what to run.
pub fn read_context(plan_dir: &Path, plan: &Plan) -> Result<Splats, SceneError> {
    let folder = context_folder(plan_dir);
    if context_finished(plan_dir, plan).is_none() {
        return Err(SceneError::invalid(
            &folder,
            "the plan's context has no finished result for this plan: run train-block --context first",
        ));
    }
    crate::splats::ply::read_splats(&folder.join("model.ply"))
}

/// A trained context.
pub struct ContextOutcome {
    pub splats: Arc<Splats>,
    pub record: ContextRecord,
    pub cancelled: bool,
}

/// Trains `plan`'s context on `dataset` (the plan's dataset, opened): the initial model of every
/// training photo, all of it trainable, `context.iters` steps at `context.scale`.
pub fn train_context(
    ctx: &mut JobContext,
    dataset: &Dataset,
    plan: &Plan,
) -> Result<ContextOutcome, JobError> {
    let started = Instant::now();
    let context = plan
        .context
        .as_ref()
        .ok_or_else(|| JobError::Invalid("the plan has no context to train".into()))?;
    let scale = context
        .image_scale()
        .ok_or_else(|| JobError::Invalid(format!("bad context scale {:?}", context.scale)))?;
    let holdout = Holdout::Auto {
        every: plan.training.test_every,
    };
    let (train, _) = split_views(dataset, &holdout).map_err(JobError::Invalid)?;
    let config = run_config(dataset, plan, scale, context.iters);
    let lights = ViewLights::new();
    let focus = Focus {
        dataset,
        scale,
        lights: &lights,
        margin_px: 0,
    };
    let views = load_photos(&focus, &config, &train)?;
    let (splats, spec) = model_and_spec(dataset, &views, &config, config.mode)?;
    ctx.log(format!(
        "context: {} photos at scale {}, {} initial Gaussians, {} steps",
        train.len(),
        context.scale,
        splats.len(),
        context.iters
    ));
    let outcome = run_training(
        ctx,
        TrainSetup {
            spec,
            splats,
            views,
            heldout: Vec::new(),
        },
        "context",
    )?;
    let record = ContextRecord {
        plan_digest: plan.digest(),
        photos: train.len(),
        steps: outcome.steps,
        scale: context.scale.clone(),
        gaussians: outcome.splats.len(),
        seconds: started.elapsed().as_secs_f64(),
        peak_rss_mb: None,
    };
    Ok(ContextOutcome {
        splats: outcome.splats,
        record,
        cancelled: outcome.cancelled,
    })
}

/// Begins the context's result folder (what dead runs left beside it is removed).
pub fn begin_context(plan_dir: &Path) -> Result<RunFolder, SceneError> {
    RunFolder::begin(&context_folder(plan_dir), CONTEXT_OUTPUTS)
}

/// Writes a trained context into its begun result folder and puts it in place.
pub fn commit_context(folder: RunFolder, outcome: &ContextOutcome) -> Result<(), SceneError> {
    commit_model(folder, &outcome.splats, "context.json", &outcome.record)
}
