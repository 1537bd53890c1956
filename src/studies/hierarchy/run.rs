//! The hierarchy study: the paper's efficiency claim measured here. Four ways to a twin at high
//! resolution — (a) full training at high resolution, (b) a coarse twin only, (c) coarse +
//! fine-tune of the damage, (d) coarse + retrain of the damage — each timed by phase and scored
//! the same way at high resolution on the held-out views.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use crate::damage::assess::{EvalRequest, evaluate_model};
use crate::damage::evaluate::DamageReadout;
use crate::damage::refine::{RefineConfig, Strategy, refine};
use crate::damage::setup::{RunConfig, prepare_run};
use crate::scene::Dataset;
use crate::splats::Splats;
use crate::studies::hierarchy::config::{HierarchyConfig, Method};
use crate::studies::hierarchy::rows::{HierarchyOutcome, HierarchyRow};
use crate::train::job::{Job, JobContext, JobError, JobOptions};
use crate::train::run::run_training;
use crate::train::views::split_views;

/// Runs the study as a job.
pub fn hierarchy_job(
    dataset: Arc<Dataset>,
    config: HierarchyConfig,
    options: JobOptions,
) -> Job<HierarchyOutcome> {
    Job::spawn("hierarchy", options, move |ctx| {
        run_hierarchy(ctx, &dataset, &config)
    })
}

/// Trains `run` on `dataset` in this job and returns the model and the seconds it took.
fn train_twin(
    ctx: &mut JobContext,
    dataset: &Dataset,
    run: &RunConfig,
    phase: &'static str,
) -> Result<(Splats, f64), JobError> {
    let started = Instant::now();
    let prepared = prepare_run(dataset, run)?;
    let outcome = run_training(ctx, prepared.setup, phase)?;
    Ok(((*outcome.splats).clone(), started.elapsed().as_secs_f64()))
}

/// The whole study in the calling job.
pub fn run_hierarchy(
    ctx: &mut JobContext,
    dataset: &Dataset,
    config: &HierarchyConfig,
) -> Result<HierarchyOutcome, JobError> {
    let (_, heldout) = split_views(dataset, &config.run.holdout).map_err(JobError::Invalid)?;
    let first = heldout
        .first()
        .ok_or_else(|| JobError::Invalid("the study needs held-out views".into()))?;
    let camera = dataset.view_camera(*first, config.fine_scale)?;
    let fine_size = (camera.intrinsics.width, camera.intrinsics.height);
    let score = |splats: &Splats| -> Result<(BTreeMap<String, f64>, f64), JobError> {
        let request = EvalRequest {
            indices: heldout.clone(),
            scale: config.fine_scale,
            background: config.run.background,
            sh_degree: splats.sh_degree,
            photometric: true,
            half_appearance: false,
            readout: DamageReadout {
                mode: config.run.mode,
                ..DamageReadout::for_model(splats, config.run.palette)
            },
        };
        let scores = evaluate_model(dataset, splats, &request, &mut |_, _| {})?;
        Ok((
            scores.damage.map(|d| d.iou).unwrap_or_default(),
            scores.psnr.unwrap_or(f64::NAN),
        ))
    };
    let mut rows = Vec::new();
    let wants = |m: Method| config.methods.contains(&m);
    let needs_coarse = [Method::Coarse, Method::Finetune, Method::Retrain]
        .into_iter()
        .any(wants);
    if needs_coarse {
        ctx.log("coarse twin");
        let coarse_run = RunConfig {
            scale: config.coarse_scale,
            iterations: config.coarse_iterations,
            ..config.run.clone()
        };
        let (coarse, coarse_s) = train_twin(ctx, dataset, &coarse_run, "coarse")?;
        if wants(Method::Coarse) {
            let (iou, psnr) = score(&coarse)?;
            rows.push(HierarchyRow {
                method: Method::Coarse,
                seconds: coarse_s,
                phases: BTreeMap::from([("coarse".to_string(), coarse_s)]),
                iou,
                psnr,
                gaussians: coarse.len(),
            });
            ctx.log(format!("coarse: {:?}", rows.last().map(|r| &r.iou)));
        }
        for (method, strategy) in [
            (Method::Finetune, Strategy::Finetune),
            (Method::Retrain, Strategy::Retrain),
        ] {
            if !wants(method) {
                continue;
            }
            ctx.log(format!("coarse + {}", method.name()));
            let refine_config = RefineConfig {
                strategy,
                scale: config.fine_scale,
                ..config.refine.clone()
            };
            let started = Instant::now();
            let outcome = refine(ctx, dataset, &coarse, &refine_config)?;
            let refine_s = started.elapsed().as_secs_f64();
            let (iou, psnr) = score(&outcome.splats)?;
            let s = &outcome.report.seconds;
            rows.push(HierarchyRow {
                method,
                seconds: coarse_s + refine_s,
                phases: BTreeMap::from([
                    ("coarse".to_string(), coarse_s),
                    ("select".to_string(), s.select),
                    ("hulls".to_string(), s.hulls),
                    ("load".to_string(), s.load),
                    ("refine".to_string(), s.refine),
                    // The refinement's own before/after scoring, part of its command.
                    ("evaluate".to_string(), s.evaluate),
                ]),
                iou,
                psnr,
                gaussians: outcome.splats.len(),
            });
            ctx.log(format!(
                "{}: {:?}",
                method.name(),
                rows.last().map(|r| &r.iou)
            ));
        }
    }
    if wants(Method::Full) {
        ctx.log("full training at high resolution");
        let full_run = RunConfig {
            scale: config.fine_scale,
            iterations: config.full_iterations,
            ..config.run.clone()
        };
        let (full, full_s) = train_twin(ctx, dataset, &full_run, "full")?;
        let (iou, psnr) = score(&full)?;
        rows.push(HierarchyRow {
            method: Method::Full,
            seconds: full_s,
            phases: BTreeMap::from([("full".to_string(), full_s)]),
            iou,
            psnr,
            gaussians: full.len(),
        });
    }
    Ok(HierarchyOutcome { rows, fine_size })
}
