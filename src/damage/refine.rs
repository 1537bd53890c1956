//! Hierarchical refinement (the paper's §2.3 and §3.2) as one job: select the coarse twin's
//! damage Gaussians, draw hull masks in every view, then train only the selection on
//! high-resolution crops of the hulls (loss inside the hulls, every other Gaussian frozen and
//! still rendered), and score the result. A configuration of the steerable trainer, not a
//! trainer of its own: the cost of a step follows the hulls' pixels, not the image's.

use std::sync::Arc;

use serde::Serialize;

use crate::damage::TrainMode;
use crate::damage::evaluate::DamageReadout;
pub use crate::damage::refine_config::RefineConfig;
pub use crate::damage::refine_quality::{Quality, StepCosts};
use crate::damage::refine_quality::{hull_coverage, quality, step_costs};
use crate::damage::refine_selection::{given_selection, region_labels, select_by_masks};
use crate::damage::select::Selection;
use crate::damage::setup::apply_mode;
use crate::metrics::{PhaseClock, PhaseTimes};
use crate::scene::Dataset;
use crate::splats::Splats;
use crate::splats::model::state;
pub use crate::train::focus::Strategy;
use crate::train::focus::{Focus, ViewHulls, ViewLights, focused_spec, trained_or_created};
use crate::train::job::{Job, JobContext, JobError, JobOptions, Progress};
use crate::train::run::{TrainSetup, run_training};
use crate::train::spec::TrainSpec;
use crate::train::views::split_views;

/// Seconds per phase (wall or CPU).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct PhaseSeconds {
    pub select: f64,
    pub hulls: f64,
    pub load: f64,
    pub refine: f64,
    pub evaluate: f64,
    pub total: f64,
}

/// What a refinement did and measured (`metrics.json`).
#[derive(Clone, Debug, Serialize)]
pub struct RefineReport {
    pub strategy: Strategy,
    pub mode: TrainMode,
    pub width: u32,
    pub height: u32,
    pub iterations: u32,
    pub filtered: usize,
    pub validated: usize,
    pub selected: usize,
    pub regions: usize,
    pub per_region_hulls: bool,
    pub train_views: usize,
    /// Hulls drawn in the training views.
    pub hulls: usize,
    /// Mean share of a training view's pixels inside its hulls.
    pub hull_fraction: f64,
    /// Per class, the share of the held-out views' reference damage pixels inside their hulls
    /// (None without reference masks): what the refinement can reach at most.
    pub hull_coverage: Option<std::collections::BTreeMap<String, f64>>,
    /// Wall seconds per phase.
    pub seconds: PhaseSeconds,
    /// CPU seconds (user + system, every thread of the process) per phase: the cost on a
    /// shared host, where wall time follows the other processes' load. None where the process's
    /// CPU time cannot be read.
    pub cpu_seconds: Option<PhaseSeconds>,
    pub selection_seconds: crate::damage::select::SelectTimes,
    pub gaussians_before: usize,
    pub gaussians_after: usize,
    pub ms_per_refine_step: f64,
    /// The refinement step by stage.
    pub stage_ms_per_step: crate::train::trainer::StageTimes,
    /// A full-image step of the same model at the same resolution, for comparison (only when
    /// `RefineConfig::cost_rounds` asked for the comparison).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ms_per_full_step: Option<f64>,
    /// That full-image step by stage.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stage_ms_per_full_step: Option<crate::train::trainer::StageTimes>,
    /// The refinement step against the full-image one, timed interleaved, with pixel counts
    /// (`bench --refine`; None unless `RefineConfig::cost_rounds` > 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub step_costs: Option<StepCosts>,
    pub before: Quality,
    pub after: Quality,
    pub views: Vec<ViewHulls>,
}

/// The refined model, the selection and the report.
#[derive(Clone, Debug)]
pub struct RefineOutcome {
    pub splats: Arc<Splats>,
    pub selection: Selection,
    pub report: RefineReport,
    pub cancelled: bool,
}

/// Starts a refinement of `model` on `dataset`.
pub fn refine_job(
    dataset: Arc<Dataset>,
    model: Arc<Splats>,
    config: RefineConfig,
    options: JobOptions,
) -> Job<RefineOutcome> {
    Job::spawn("refine", options, move |ctx| {
        refine(ctx, &dataset, &model, &config)
    })
}

/// The whole refinement, in the calling job.
pub fn refine(
    ctx: &mut JobContext,
    dataset: &Dataset,
    model: &Splats,
    config: &RefineConfig,
) -> Result<RefineOutcome, JobError> {
    refine_from(ctx, dataset, &ViewLights::new(), model, model, config)
}

/// `refine` of `model` on photos whose light differs from the twin's by `lights` (a later
/// survey's), scored before against `baseline`: the twin as it was, when the caller added
/// Gaussians to it for the refinement to train (the update's new-damage seeds).
pub fn refine_from(
    ctx: &mut JobContext,
    dataset: &Dataset,
    lights: &ViewLights,
    baseline: &Splats,
    model: &Splats,
    config: &RefineConfig,
) -> Result<RefineOutcome, JobError> {
    let started = PhaseClock::start();
    let mut times = PhaseTimes::<PhaseSeconds>::new();
    let mode = config.select.mode;
    let (train_idx, heldout_idx) =
        split_views(dataset, &config.holdout).map_err(JobError::Invalid)?;
    let masks = dataset.masks.clone().ok_or_else(|| {
        JobError::Invalid(format!(
            "{} has no damage masks to select damage Gaussians with",
            dataset.root.display()
        ))
    })?;

    // 1. Select, against the training views' own masks at the selection scale (or take the
    // person's selection as it is).
    let t = PhaseClock::start();
    let selection = match &config.given {
        Some(given) => given_selection(model, given),
        None => select_by_masks(ctx, dataset, model, config, &train_idx, masks.as_ref())?,
    };
    let n = model.len();
    times.record(&t, |p| &mut p.select);
    ctx.log(format!(
        "selection: {} filtered, {} validated, {} with neighbours",
        selection.filtered.len(),
        selection.validated.len(),
        selection.selected.len()
    ));
    if selection.selected.is_empty() {
        return Err(JobError::Invalid(
            "no damage Gaussians were selected: nothing to refine".into(),
        ));
    }

    // 2. Hulls in every view at the refinement scale.
    let t = PhaseClock::start();
    let region_of = region_labels(model, &selection, config);
    let region_count = region_of
        .iter()
        .copied()
        .max()
        .map_or(0, |m| m as usize + 1);
    let all: Vec<(usize, bool)> = train_idx
        .iter()
        .map(|&i| (i, false))
        .chain(heldout_idx.iter().map(|&i| (i, true)))
        .collect();
    let focus = Focus {
        dataset,
        scale: config.scale,
        lights,
        margin_px: config.crop_margin_px,
    };
    let mut views = focus.draw_hulls(
        model,
        &selection.selected,
        &region_of,
        &all,
        &config.hulls,
        config.background,
        &mut |done, total| {
            ctx.progress(Progress::counted("hulls", done, total, n));
        },
    )?;
    if config.hulls_from_truth {
        crate::damage::truth_hulls::replace_with_truth_hulls(
            dataset,
            &mut views,
            config.scale,
            config.hulls.dilate_px,
        )?;
    }
    times.record(&t, |p| &mut p.hulls);

    // 3. The crops of the training views' hulls, at the refinement scale.
    let t = PhaseClock::start();
    let trained: Vec<&ViewHulls> = views
        .iter()
        .filter(|v| !v.heldout && !v.hulls.is_empty())
        .collect();
    if trained.is_empty() {
        return Err(JobError::Invalid(
            "the selection's hulls are empty in every training view".into(),
        ));
    }
    let labels = mode == TrainMode::Label;
    let palette = config.select.palette;
    let targets = move |views: &mut [_]| apply_mode(views, mode, &palette);
    let crops = focus.load_crops(&trained, mode.uses_masks(), &targets)?;
    let hull_fraction = trained
        .iter()
        .map(|v| v.pixels as f64 / (v.width as f64 * v.height as f64))
        .sum::<f64>()
        / trained.len() as f64;
    ctx.log(format!(
        "refining {} Gaussians in {} training views ({:.1} % of their pixels in hulls)",
        selection.selected.len(),
        trained.len(),
        100.0 * hull_fraction
    ));
    times.record(&t, |p| &mut p.load);

    // 4. Train the selection.
    let t = PhaseClock::start();
    let mut spec = refine_spec(config, model, &selection.selected, labels);
    if let Some(rate) = config.neighbour_geometry_rate {
        let mut rates = vec![rate; n];
        for &g in &selection.validated {
            rates[g as usize] = 1.0;
        }
        spec.geometry_rate = Some(rates);
    }
    // The cost comparison, when asked for (`bench --refine`): the run's step against a
    // full-image step, interleaved. Off by default: it costs a dozen full-image steps.
    let costs = if config.cost_rounds > 0 {
        Some(step_costs(
            &focus,
            model,
            &spec,
            &trained,
            &crops,
            &targets,
            mode,
            config.cost_rounds,
        )?)
    } else {
        None
    };
    let setup = TrainSetup {
        spec,
        splats: model.clone(),
        views: crops,
        heldout: Vec::new(),
    };
    let outcome = run_training(ctx, setup, "refine")?;
    times.record(&t, |p| &mut p.refine);
    let mut refined = (*outcome.splats).clone();
    mark_refined(&mut refined, model, &selection);

    // 5. Score before and after on the held-out views.
    let t = PhaseClock::start();
    let readout = DamageReadout {
        mode,
        ..DamageReadout::for_model(baseline, config.select.palette)
    };
    let heldout: Vec<&ViewHulls> = views.iter().filter(|v| v.heldout).collect();
    let before = quality(&focus, baseline, &heldout, config.background, &readout)?;
    let after = quality(&focus, &refined, &heldout, config.background, &readout)?;
    let hull_coverage = hull_coverage(&focus, &heldout)?;
    times.record(&t, |p| &mut p.evaluate);
    times.record(&started, |p| &mut p.total);

    let (width, height) = (views[0].width, views[0].height);
    let report = RefineReport {
        strategy: config.strategy,
        mode,
        width,
        height,
        iterations: outcome.steps,
        filtered: selection.filtered.len(),
        validated: selection.validated.len(),
        selected: selection.selected.len(),
        regions: region_count,
        per_region_hulls: config.hulls.per_region,
        train_views: trained.len(),
        hulls: trained.iter().map(|v| v.hull_count).sum(),
        hull_fraction,
        hull_coverage,
        seconds: times.wall,
        cpu_seconds: times.cpu,
        selection_seconds: selection.seconds,
        gaussians_before: baseline.len(),
        gaussians_after: refined.len(),
        ms_per_refine_step: outcome.timings.total * 1000.0 / outcome.steps.max(1) as f64,
        ms_per_full_step: costs.as_ref().map(|c| c.full_ms.total),
        stage_ms_per_full_step: costs.as_ref().map(|c| c.full_ms.clone()),
        step_costs: costs,
        stage_ms_per_step: outcome.timings.per_step_ms(outcome.steps),
        before,
        after,
        views,
    };
    Ok(RefineOutcome {
        splats: Arc::new(refined),
        selection,
        report,
        cancelled: outcome.cancelled,
    })
}

/// The refinement's training spec: the focused run on the selection `trainable`, with the
/// damage supervision and rates of `config`.
fn refine_spec(
    config: &RefineConfig,
    model: &Splats,
    trainable: &[u32],
    labels: bool,
) -> TrainSpec {
    let mut spec = focused_spec(
        model,
        trainable,
        config.strategy,
        config.iterations,
        config.seed,
        config.background,
    );
    let iterations = spec.iterations;
    spec.targets.label_weight = if labels && model.label_channels > 0 {
        config.label_weight
    } else {
        0.0
    };
    spec.targets.label_pos_weight = config.label_pos_weight;
    spec.targets.label_geometry_steps =
        crate::damage::setup::geometry_steps(config.label_geometry_until, iterations);
    spec.lr = config.rates();
    spec.max_scale_growth = config.max_scale_growth;
    spec.backend = config.backend;
    spec.stop_when_flat = config.stop_when_flat;
    spec
}

/// Gaussians the refinement trained (the selection) or created, marked `REFINED`.
fn mark_refined(refined: &mut Splats, input: &Splats, selection: &Selection) {
    let touched = trained_or_created(refined, input, &selection.selected, input.meta.next_id());
    for (g, touched) in touched.into_iter().enumerate() {
        if touched {
            refined.meta.state[g] |= state::REFINED;
        }
    }
}
