//! The hierarchy study: the paper's efficiency claim measured here. Four ways to a twin at high
//! resolution — (a) full training at high resolution, (b) a coarse twin only, (c) coarse +
//! fine-tune of the damage, (d) coarse + retrain of the damage — each timed by phase and scored
//! the same way at high resolution on the held-out views.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::damage::Palette;
use crate::damage::assess::{EvalRequest, evaluate_model};
use crate::damage::evaluate::DamageReadout;
use crate::damage::refine::{RefineConfig, Strategy, refine};
use crate::damage::setup::{RunConfig, prepare_run};
use crate::scene::{Dataset, ImageScale};
use crate::splats::Splats;
use crate::train::job::{Job, JobContext, JobError, JobOptions};
use crate::train::run::run_training;
use crate::train::views::split_views;

/// The four methods.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    Full,
    Coarse,
    Finetune,
    Retrain,
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::Full => "full",
            Method::Coarse => "coarse",
            Method::Finetune => "finetune",
            Method::Retrain => "retrain",
        }
    }
}

/// The study's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct HierarchyConfig {
    /// The run every method starts from (mode, palette, held-out rule, seed, background); its
    /// scale and iterations are replaced per method.
    pub run: RunConfig,
    pub coarse_scale: ImageScale,
    pub coarse_iterations: u32,
    /// "High resolution": where the full run trains, refinements refine and everything is
    /// scored.
    pub fine_scale: ImageScale,
    pub full_iterations: u32,
    pub refine: RefineConfig,
    pub methods: Vec<Method>,
}

/// One method's figures (`hierarchy-study.json` `rows`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HierarchyRow {
    pub method: Method,
    /// Wall time of everything the method needs (a refinement includes its coarse twin).
    pub seconds: f64,
    /// Wall time per phase.
    pub phases: BTreeMap<String, f64>,
    /// Held-out IoU per class at high resolution.
    pub iou: BTreeMap<String, f64>,
    /// Held-out PSNR at high resolution.
    pub psnr: f64,
    pub gaussians: usize,
}

/// What the study produced.
#[derive(Clone, Debug)]
pub struct HierarchyOutcome {
    pub rows: Vec<HierarchyRow>,
    /// Width and height of "high resolution".
    pub fine_size: (u32, u32),
}

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

/// The study's default settings on the demo building (960×540): a 240×135 coarse twin of 3000
/// steps, 1000 refinement steps at 960×540, and a 960×540 full run of 3000 steps.
pub fn default_config(palette: Palette) -> HierarchyConfig {
    HierarchyConfig {
        run: RunConfig {
            palette,
            ..RunConfig::default()
        },
        coarse_scale: ImageScale::Factor(4),
        coarse_iterations: 3000,
        fine_scale: ImageScale::Factor(1),
        full_iterations: 3000,
        refine: RefineConfig::default(),
        methods: vec![
            Method::Coarse,
            Method::Finetune,
            Method::Retrain,
            Method::Full,
        ],
    }
}
