//! The hierarchy study: the paper's efficiency claim measured here. Four ways to a twin at high
//! resolution — (a) full training at high resolution, (b) a coarse twin only, (c) coarse +
//! fine-tune of the damage, (d) coarse + retrain of the damage — each timed by phase and scored
//! the same way at high resolution on the held-out views.

use std::collections::BTreeMap;
use std::sync::Arc;

use crate::damage::assess::{EvalRequest, evaluate_model};
use crate::damage::evaluate::DamageReadout;
use crate::damage::refine::{RefineConfig, Strategy, refine};
use crate::damage::setup::{RunConfig, prepare_run};
use crate::metrics::PhaseClock;
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

/// Wall and CPU seconds of one phase (CPU None where unreadable).
#[derive(Clone, Copy, Debug)]
struct Cost {
    wall: f64,
    cpu: Option<f64>,
}

impl Cost {
    fn of(clock: &PhaseClock) -> Cost {
        Cost {
            wall: clock.wall_seconds(),
            cpu: clock.cpu_seconds(),
        }
    }
}

/// A row's `phases` and `cpu_phases` from its named phase costs (`cpu_phases` empty unless
/// every phase's CPU time was read).
fn phase_maps(phases: &[(&str, Cost)]) -> (BTreeMap<String, f64>, BTreeMap<String, f64>) {
    let wall = phases
        .iter()
        .map(|(name, c)| (name.to_string(), c.wall))
        .collect();
    let cpu = phases
        .iter()
        .map(|(name, c)| Some((name.to_string(), c.cpu?)))
        .collect::<Option<BTreeMap<_, _>>>()
        .unwrap_or_default();
    (wall, cpu)
}

/// Trains `run` on `dataset` in this job and returns the model and what it cost: loading and
/// training, without the trainer's final held-out scoring (the study scores every method
/// itself, outside the counted time).
fn train_twin(
    ctx: &mut JobContext,
    dataset: &Dataset,
    run: &RunConfig,
    phase: &'static str,
) -> Result<(Splats, Cost), JobError> {
    let clock = PhaseClock::start();
    let mut prepared = prepare_run(dataset, run)?;
    prepared.setup.heldout.clear();
    let outcome = run_training(ctx, prepared.setup, phase)?;
    Ok(((*outcome.splats).clone(), Cost::of(&clock)))
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
        let (coarse, coarse_cost) = train_twin(ctx, dataset, &coarse_run, "coarse")?;
        if wants(Method::Coarse) {
            let (iou, psnr) = score(&coarse)?;
            let (phases, cpu_phases) = phase_maps(&[("coarse", coarse_cost)]);
            rows.push(HierarchyRow {
                method: Method::Coarse,
                seconds: coarse_cost.wall,
                phases,
                cpu_seconds: coarse_cost.cpu,
                cpu_phases,
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
            let clock = PhaseClock::start();
            let outcome = refine(ctx, dataset, &coarse, &refine_config)?;
            let refine_cost = Cost::of(&clock);
            let (iou, psnr) = score(&outcome.splats)?;
            let wall = &outcome.report.seconds;
            let cpu = outcome.report.cpu_seconds.as_ref();
            let phase = |pick: fn(&crate::damage::refine::PhaseSeconds) -> f64| Cost {
                wall: pick(wall),
                cpu: cpu.map(pick),
            };
            let evaluate = phase(|p| p.evaluate);
            // The refinement's own before/after scoring is left out like the trainers' final
            // one: every method is counted up to its twin, and scored by the study alone.
            let counted = Cost {
                wall: refine_cost.wall - evaluate.wall,
                cpu: refine_cost.cpu.zip(evaluate.cpu).map(|(r, e)| r - e),
            };
            let (phases, cpu_phases) = phase_maps(&[
                ("coarse", coarse_cost),
                ("select", phase(|p| p.select)),
                ("hulls", phase(|p| p.hulls)),
                ("load", phase(|p| p.load)),
                ("refine", phase(|p| p.refine)),
            ]);
            rows.push(HierarchyRow {
                method,
                seconds: coarse_cost.wall + counted.wall,
                phases,
                cpu_seconds: coarse_cost.cpu.zip(counted.cpu).map(|(a, b)| a + b),
                cpu_phases,
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
        let (full, full_cost) = train_twin(ctx, dataset, &full_run, "full")?;
        let (iou, psnr) = score(&full)?;
        let (phases, cpu_phases) = phase_maps(&[("full", full_cost)]);
        rows.push(HierarchyRow {
            method: Method::Full,
            seconds: full_cost.wall,
            phases,
            cpu_seconds: full_cost.cpu,
            cpu_phases,
            iou,
            psnr,
            gaussians: full.len(),
        });
    }
    Ok(HierarchyOutcome { rows, fine_size })
}
