//! Compaction as a job: a trained model pruned to its `keep` most important Gaussians (blending
//! weight over the training views, `train::importance`), then fine-tuned briefly as a
//! continuation of itself. The views and the fine-tune's spec arrive built by the caller
//! (`damage::compact` builds them through `prepare_run`, like every other run); reads no files.

use std::sync::Arc;
use std::time::Instant;

use crate::raster::RenderSettings;
use crate::splats::Splats;
use crate::train::importance::{importance, prune_to};
use crate::train::job::{Job, JobContext, JobError, JobOptions};
use crate::train::run::{TrainSetup, run_training};
use crate::train::spec::{DensifyPolicy, TrainSpec, gentle_learning_rates};

/// What a compaction works on.
pub struct CompactSetup {
    /// The trained model to compact (`run.splats`), the training views importance is summed over
    /// and the fine-tune trains on, and the fine-tune's spec (made a continuation here:
    /// `continuation`; its background is also importance's). Held-out views are not used.
    pub run: TrainSetup,
    /// Gaussians to keep.
    pub keep: usize,
    /// Fine-tune after the prune (false: prune only).
    pub finetune: bool,
    /// Also return the model as pruned, before the fine-tune (`CompactOutcome::pruned`).
    pub keep_pruned: bool,
}

/// A compacted model.
#[derive(Clone, Debug)]
pub struct CompactOutcome {
    pub splats: Splats,
    /// Gaussians before the prune.
    pub before: usize,
    /// The model right after the prune, when `CompactSetup::keep_pruned` asked for it.
    pub pruned: Option<Splats>,
    /// Importance, prune and fine-tune, pauses excluded (view loading excluded).
    pub seconds: f64,
    /// The fine-tune was cancelled before its last step.
    pub cancelled: bool,
}

/// A compaction job.
pub type CompactJob = Job<CompactOutcome>;

/// Starts compacting what is already in memory.
pub fn compact(setup: CompactSetup, options: JobOptions) -> CompactJob {
    compact_with(move |_| Ok(setup), options)
}

/// Starts a compaction whose inputs are produced on the worker by `setup` (dataset loading),
/// which may log through the context.
pub fn compact_with<F>(setup: F, options: JobOptions) -> CompactJob
where
    F: FnOnce(&mut JobContext) -> Result<CompactSetup, JobError> + Send + 'static,
{
    Job::spawn("compact", options, move |ctx| {
        let setup = setup(ctx)?;
        run_compaction(ctx, setup)
    })
}

/// Makes `spec` a continuation of a trained model of SH degree `sh_degree`, not a restart: the
/// pruned set keeps its size (no densification) and moves at the timeline update's gentle rates,
/// labels stay as they are, and every SH band trains from the first step.
pub fn continuation(spec: &mut TrainSpec, sh_degree: u32) {
    spec.densify = DensifyPolicy::Off;
    spec.groups.raw_labels = false;
    spec.sh_degree = sh_degree;
    spec.sh_ramp_every = 1;
    spec.lr = gentle_learning_rates();
}

/// Prunes and fine-tunes `setup` in the calling job (the fine-tune reports as phase
/// `"fine-tune"`).
pub fn run_compaction(
    ctx: &mut JobContext,
    setup: CompactSetup,
) -> Result<CompactOutcome, JobError> {
    let CompactSetup {
        run,
        keep,
        finetune,
        keep_pruned,
    } = setup;
    let TrainSetup {
        mut spec,
        mut splats,
        views,
        ..
    } = run;
    let started = Instant::now();
    let before = splats.len();
    let settings = RenderSettings::new(spec.background, splats.sh_degree);
    let score = importance(&splats, &views, &settings);
    prune_to(&mut splats, &score, keep);
    let mut seconds = started.elapsed().as_secs_f64();
    ctx.log(format!(
        "pruned {before} → {} Gaussians by importance over {} training views",
        splats.len(),
        views.len()
    ));
    let pruned = keep_pruned.then(|| splats.clone());
    let mut cancelled = false;
    if finetune {
        continuation(&mut spec, splats.sh_degree);
        let setup = TrainSetup {
            spec,
            splats,
            views,
            heldout: Vec::new(),
        };
        let outcome = run_training(ctx, setup, "fine-tune")?;
        seconds += outcome.seconds;
        cancelled = outcome.cancelled;
        splats = Arc::try_unwrap(outcome.splats).unwrap_or_else(|shared| (*shared).clone());
    }
    Ok(CompactOutcome {
        splats,
        before,
        pruned,
        seconds,
        cancelled,
    })
}
