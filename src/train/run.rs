//! A training run under job control: steps the `Trainer` until done or cancelled, reporting
//! progress, held-out PSNR, rate-limited snapshots and rolled-back steps through the job's
//! context. Every job that trains (train, refine, survey update) runs this loop.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::splats::Splats;
use crate::train::backend_choice::open_backend;
use crate::train::evaluate::EvalScores;
use crate::train::job::{Job, JobContext, JobError, JobOptions, Progress};
use crate::train::plateau::PlateauWatch;
use crate::train::spec::{TrainSpec, TrainView};
use crate::train::trainer::{StageTimes, TrainError, Trainer};

/// What a training run trains: the spec, the initial model, the views and the held-out views
/// (built on the worker, so that loading a dataset does not block the caller).
pub struct TrainSetup {
    pub spec: TrainSpec,
    pub splats: Splats,
    pub views: Vec<TrainView>,
    /// Held-out views for PSNR during and after training (may be empty).
    pub heldout: Vec<TrainView>,
}

/// What a finished (or cancelled) run leaves.
#[derive(Clone, Debug)]
pub struct TrainOutcome {
    pub splats: Arc<Splats>,
    pub steps: u32,
    pub total: u32,
    pub cancelled: bool,
    /// Training time, pauses excluded, held-out evaluations included.
    pub seconds: f64,
    /// Held-out scores of the final model (None when no held-out views were given).
    pub heldout: Option<EvalScores>,
    /// Steps whose NaN/Inf was rolled back.
    pub rolled_back: u32,
    /// Accumulated time per stage over the run.
    pub timings: StageTimes,
    /// Each training view's learnt light, in the spec's view order (empty unless the spec
    /// learns it: `TrainSpec::appearance`).
    pub appearance: Vec<crate::scene::project::ColourTransform>,
    /// The renderer that trained, in words ("CPU rasterizer", "GPU: <adapter>, <accumulation>").
    pub renderer: String,
}

/// A training job.
pub type TrainJob = Job<TrainOutcome>;

/// Starts training what is already in memory.
pub fn train(setup: TrainSetup, options: JobOptions) -> TrainJob {
    train_with(move |_| Ok(setup), options)
}

/// Starts a training job whose inputs are produced on the worker by `setup` (dataset loading,
/// initialisation), which may log through the context.
pub fn train_with<F>(setup: F, options: JobOptions) -> TrainJob
where
    F: FnOnce(&mut JobContext) -> Result<TrainSetup, JobError> + Send + 'static,
{
    Job::spawn("train", options, move |ctx| {
        let setup = setup(ctx)?;
        run_training(ctx, setup, "train")
    })
}

/// Runs `setup` to the end (or until cancelled) in the calling job, reporting as `phase`.
pub fn run_training(
    ctx: &mut JobContext,
    setup: TrainSetup,
    phase: &'static str,
) -> Result<TrainOutcome, JobError> {
    let TrainSetup {
        spec,
        splats,
        views,
        heldout,
    } = setup;
    let eval_every = spec.eval_every;
    let mut plateau = spec.stop_when_flat.map(PlateauWatch::new);
    let choice = spec.backend;
    let (backend, renderer) = open_backend(choice).map_err(|source| TrainError::Backend {
        backend: choice,
        source,
    })?;
    let mut trainer = Trainer::with_backend(spec, splats, views, backend)?;
    let total = trainer.total_steps();
    ctx.log(format!(
        "training {} Gaussians on {} views for {total} steps ({renderer})",
        trainer.splats().len(),
        trainer.view_count()
    ));

    let mut train_time = Duration::ZERO;
    let mut cancelled = false;
    let mut rolled_back = 0;
    while !trainer.is_done() {
        if ctx.should_stop() {
            cancelled = true;
            break;
        }
        let started = Instant::now();
        let report = trainer.step();
        if let Some(fault) = trainer.renderer_fault() {
            return Err(TrainError::RendererFault(fault.to_string()).into());
        }
        if let Some(reason) = report.rolled_back {
            rolled_back += 1;
            ctx.rolled_back(report.step, reason);
        }
        let step = trainer.steps_done();
        let psnr =
            if !heldout.is_empty() && eval_every > 0 && step % eval_every == 0 && step < total {
                Some(trainer.evaluate(&heldout).psnr)
            } else {
                None
            };
        train_time += started.elapsed();
        let per_step = train_time.as_secs_f64() / step.max(1) as f64;
        let progress = Progress {
            phase,
            step,
            total,
            loss: report.loss,
            psnr,
            gaussians: trainer.splats().len(),
            elapsed: train_time,
            eta: Duration::from_secs_f64(per_step * (total - step.min(total)) as f64),
        };
        if !ctx.progress(progress) {
            // Nobody listens any more: stop working for nobody.
            cancelled = true;
            break;
        }
        ctx.snapshot_every(|| {
            trainer.sync();
            trainer.splats().clone()
        });
        if plateau.as_mut().is_some_and(|p| p.push(report.loss)) {
            ctx.log(format!(
                "the loss stopped improving: stopped at step {step} of {total}"
            ));
            break;
        }
    }

    let started = Instant::now();
    let final_scores = (!heldout.is_empty()).then(|| trainer.evaluate(&heldout));
    train_time += started.elapsed();
    let steps = trainer.steps_done();
    let timings = trainer.timings().clone();
    let appearance = trainer.appearance();
    let splats = Arc::new(trainer.into_splats());
    ctx.snapshot(splats.clone());
    Ok(TrainOutcome {
        splats,
        steps,
        total,
        cancelled,
        seconds: train_time.as_secs_f64(),
        heldout: final_scores,
        rolled_back,
        timings,
        appearance,
        renderer,
    })
}
