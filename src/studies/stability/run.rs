//! One twin of the stability suite: trained with a perturbation of its training views and scored
//! on the held-out views (PSNR, SSIM, damage IoU against the clean masks). The held-out views and
//! their poses are never perturbed, so every row is scored against the same truth. Reads no
//! files beyond the dataset.

use std::collections::BTreeMap;

use crate::damage::assess::{EvalRequest, evaluate_model};
use crate::damage::evaluate::DamageReadout;
use crate::damage::setup::{RunConfig, prepare_run};
use crate::damage::{Palette, TrainMode};
use crate::scene::Dataset;
use crate::studies::stability::perturb::{Perturbation, perturb};
use crate::studies::stability::row::StabilityRow;
use crate::train::job::JobOptions;
use crate::train::run::train;

/// Trains `config` on `dataset` with `perturbation` applied to the training views and scores
/// the result on the held-out views. `axis` and `value` name the row.
pub fn stability_run(
    dataset: &Dataset,
    config: &RunConfig,
    perturbation: Perturbation,
    axis: &str,
    value: f64,
    threads: Option<usize>,
) -> Result<StabilityRow, String> {
    let name = |e: String| format!("{axis} = {value}: {e}");
    let mut run = prepare_run(dataset, config).map_err(|e| name(e.to_string()))?;
    perturb(&mut run.setup.views, perturbation).map_err(name)?;
    let views = &run.setup.views;
    let (width, height) = (views[0].image.width, views[0].image.height);
    let heldout_indices = run.heldout_indices.clone();
    run.setup.heldout.clear(); // scored below, once, not during training
    let outcome = train(run.setup, JobOptions::headless(threads))
        .wait()
        .map_err(|e| name(e.to_string()))?;
    let readout = DamageReadout {
        mode: run.mode,
        ..DamageReadout::for_model(&outcome.splats, Palette::default())
    };
    let scores = evaluate_model(
        dataset,
        &outcome.splats,
        &EvalRequest {
            indices: heldout_indices,
            scale: config.scale,
            background: config.background,
            sh_degree: config.sh_degree,
            photometric: true,
            half_appearance: false,
            readout,
        },
        &mut |_, _| {},
    )
    .map_err(|e| name(e.to_string()))?;
    Ok(StabilityRow {
        axis: axis.to_string(),
        value,
        psnr: scores.psnr.unwrap_or(f64::NAN),
        ssim: scores.ssim,
        iou: match (&scores.damage, run.mode) {
            (Some(d), TrainMode::Label | TrainMode::Overlay) => d.iou.clone(),
            _ => BTreeMap::new(),
        },
        gaussians: outcome.splats.len(),
        seconds: outcome.seconds,
        width,
        height,
    })
}
