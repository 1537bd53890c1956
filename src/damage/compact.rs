//! Compacting a trained model on its dataset: the training views and the fine-tune's spec built
//! by `prepare_run` like every run's, handed to the train-level compaction job
//! (`train::compact`); and the photos' held-out PSNR that `compact` and the budget study report.
//! The CLI, the studies and the app all compact through here.

use std::sync::Arc;

use glam::Vec3;

use crate::damage::TrainMode;
use crate::damage::assess::{EvalRequest, evaluate_model};
use crate::damage::evaluate::DamageReadout;
use crate::damage::setup::{RunConfig, prepare_run};
use crate::scene::{Dataset, ImageScale, SceneError};
use crate::splats::Splats;
use crate::train::compact::{CompactJob, CompactSetup, compact_with};
use crate::train::job::{JobError, JobOptions};
use crate::train::spec::Targets;
use crate::train::views::Holdout;

/// How to compact a model on the dataset it was trained on.
#[derive(Clone, Debug, PartialEq)]
pub struct CompactConfig {
    /// Gaussians to keep.
    pub keep: usize,
    /// Fine-tuning steps after the prune (0: prune only).
    pub iterations: u32,
    /// Scale of the training views (importance and fine-tune).
    pub scale: ImageScale,
    /// Which views are held out: the rest are the training views.
    pub holdout: Holdout,
    pub background: Vec3,
    pub seed: u64,
    /// Also return the model as pruned, before the fine-tune.
    pub keep_pruned: bool,
}

impl CompactConfig {
    /// The fine-tune's run for a model of SH degree `sh_degree`: photos only (the model's labels
    /// are kept as they are, not trained), no held-out evaluation. Its spec is then made a
    /// continuation (`train::compact::continuation`).
    fn run_config(&self, sh_degree: u32) -> RunConfig {
        RunConfig {
            mode: TrainMode::Rgb,
            scale: self.scale,
            iterations: self.iterations,
            holdout: self.holdout.clone(),
            sh_degree,
            seed: self.seed,
            background: self.background,
            // No label loss in RGB mode; the spec's label targets stay a plain reconstruction's,
            // as they were when `compact` built its spec by hand.
            label_pos_weight: Targets::default().label_pos_weight,
            // `prepare_run` builds an initial model, replaced here by the trained one: on a
            // dataset without points, one random point keeps that cost nil.
            random_points: 1,
            eval_every: 0,
            ..RunConfig::default()
        }
    }
}

/// The compaction of `model` on `dataset`: its training views loaded by `prepare_run` at
/// `config.scale` with the fine-tune's spec.
pub fn prepare_compaction(
    dataset: &Dataset,
    model: Splats,
    config: &CompactConfig,
) -> Result<CompactSetup, JobError> {
    let mut run = prepare_run(dataset, &config.run_config(model.sh_degree))?;
    run.setup.splats = model;
    run.setup.heldout.clear();
    Ok(CompactSetup {
        run: run.setup,
        keep: config.keep,
        finetune: config.iterations > 0,
        keep_pruned: config.keep_pruned,
    })
}

/// Starts compacting `model` on `dataset`; the views load on the worker.
pub fn compact_job(
    dataset: Arc<Dataset>,
    model: Splats,
    config: CompactConfig,
    options: JobOptions,
) -> CompactJob {
    compact_with(
        move |_| prepare_compaction(&dataset, model, &config),
        options,
    )
}

/// Mean held-out PSNR of `splats` on the views `indices` of `dataset` (photos only; NaN when
/// there are none).
pub fn heldout_psnr(
    dataset: &Dataset,
    splats: &Splats,
    indices: &[usize],
    scale: ImageScale,
    background: Vec3,
) -> Result<f64, SceneError> {
    let request = EvalRequest {
        indices: indices.to_vec(),
        scale,
        background,
        sh_degree: splats.sh_degree,
        photometric: true,
        half_appearance: false,
        readout: DamageReadout {
            mode: TrainMode::Rgb,
            ..DamageReadout::for_model(splats, Default::default())
        },
    };
    let scores = evaluate_model(dataset, splats, &request, &mut |_, _| {})?;
    Ok(scores.psnr.unwrap_or(f64::NAN))
}
