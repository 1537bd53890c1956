//! Hierarchical refinement (the paper's §2.3 and §3.2) as one job: select the coarse twin's
//! damage Gaussians, draw hull masks in every view, then train only the selection on
//! high-resolution crops of the hulls (loss inside the hulls, every other Gaussian frozen and
//! still rendered), and score the result. A configuration of the steerable trainer, not a
//! trainer of its own: the cost of a step follows the hulls' pixels, not the image's.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;

use crate::damage::TrainMode;
use crate::damage::evaluate::DamageReadout;
use crate::damage::hulls::{Hull, HullConfig, union_mask, view_hulls};
pub use crate::damage::refine_quality::Quality;
use crate::damage::refine_quality::{full_step_ms, quality};
use crate::damage::refine_selection::{given_selection, region_labels, select_by_masks};
use crate::damage::select::{SelectConfig, Selection};
use crate::damage::setup::apply_mode;
use crate::raster::RenderSettings;
use crate::raster::weight_lift::WeightLift;
use crate::scene::project::ColourTransform;
use crate::scene::{Dataset, ImageScale, Mask};
use crate::splats::Splats;
use crate::splats::model::state;
use crate::train::densify::DensifyConfig;
use crate::train::job::{Job, JobContext, JobError, JobOptions, Progress};
use crate::train::run::{TrainSetup, run_training};
use crate::train::spec::{DensifyPolicy, TrainSpec, TrainView, densify_for_iterations};
use crate::train::views::{Holdout, load_views, split_views};

/// Fine-tune the selection as it is, or let it densify (clone, split, prune) as it trains.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Strategy {
    /// Position, colour, opacity, scale, rotation and labels of the selection; count unchanged.
    Finetune,
    /// The same plus density control restricted to the selection; new Gaussians are trainable
    /// and inherit their parent's damage labels and state.
    Retrain,
}

impl std::str::FromStr for Strategy {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "finetune" => Ok(Strategy::Finetune),
            "retrain" => Ok(Strategy::Retrain),
            _ => Err(format!(
                "unknown strategy {text:?}: use finetune or retrain"
            )),
        }
    }
}

/// Everything a refinement is steered by.
#[derive(Clone, Debug, PartialEq)]
pub struct RefineConfig {
    pub select: SelectConfig,
    pub hulls: HullConfig,
    pub strategy: Strategy,
    /// The high resolution the selection is refined at.
    pub scale: ImageScale,
    /// The resolution of the masks the selection is validated against.
    pub select_scale: ImageScale,
    pub iterations: u32,
    /// Held-out views: never trained on, scored before and after.
    pub holdout: Holdout,
    pub background: Vec3,
    pub seed: u64,
    /// Pixels of context kept around each hull's box in its crop.
    pub crop_margin_px: u32,
    /// Regions join selected Gaussians within this many median neighbour spacings.
    pub region_spacings: f32,
    /// Weight of the label loss and of damage pixels in it (label mode).
    pub label_weight: f32,
    pub label_pos_weight: f32,
    /// The fraction of the refinement during which the label loss shapes the geometry
    /// (`Targets::label_geometry_steps`; None: all of it).
    pub label_geometry_until: Option<f32>,
    pub label_lr: Option<f32>,
    /// Per view index, how its photo's light differs from the twin's: the photos are mapped
    /// into the twin's look before training and scoring (a later survey's light must not
    /// repaint the twin).
    pub appearance: BTreeMap<usize, ColourTransform>,
    /// Refine these Gaussians (a person's selection) instead of selecting damage by the masks.
    pub given: Option<Vec<u32>>,
    /// Learning rates other than the from-scratch ones (the label rate is `label_lr`).
    pub lr: crate::train::spec::LrOverrides,
    /// Each refined Gaussian's scale stays within this factor of its size before (None: free).
    pub max_scale_growth: Option<f32>,
    /// A factor on the position, scale, rotation and opacity rates of the selected Gaussians that
    /// are only neighbours of damage (None: full rates; `TrainSpec::geometry_rate`).
    pub neighbour_geometry_rate: Option<f32>,
    /// The renderer the refinement trains on.
    pub backend: crate::train::backend_choice::Backend,
}

impl Default for RefineConfig {
    fn default() -> Self {
        let run = crate::damage::setup::RunConfig::default();
        RefineConfig {
            select: SelectConfig::default(),
            hulls: HullConfig::default(),
            strategy: Strategy::Finetune,
            scale: ImageScale::Factor(1),
            select_scale: ImageScale::Factor(4),
            iterations: 1000,
            holdout: Holdout::Auto { every: 8 },
            background: Vec3::ZERO,
            seed: 0,
            crop_margin_px: 8,
            region_spacings: 6.0,
            label_weight: run.label_weight,
            // Measured on the demo building (docs/DAMAGE.md, retrain 1000 steps at 960×540):
            // the coarse run's 4 leaves cracks too wide at full resolution (precision 0.72 against
            // recall 0.95, IoU 0.69); 2 balances them (0.80 / 0.89, IoU 0.73) and 1 loses rebar
            // recall (0.53).
            label_pos_weight: 2.0,
            label_geometry_until: run.label_geometry_until,
            label_lr: run.label_lr,
            appearance: BTreeMap::new(),
            given: None,
            lr: crate::train::spec::LrOverrides::default(),
            max_scale_growth: None,
            neighbour_geometry_rate: None,
            backend: Default::default(),
        }
    }
}

/// Hulls of one view.
#[derive(Clone, Debug, Serialize)]
pub struct ViewHulls {
    pub view: String,
    pub index: usize,
    pub heldout: bool,
    pub width: u32,
    pub height: u32,
    #[serde(skip)]
    pub hulls: Vec<Hull>,
    pub hull_count: usize,
    /// Pixels inside any hull.
    pub pixels: usize,
}

impl ViewHulls {
    pub fn union(&self) -> Mask {
        union_mask(&self.hulls, self.width, self.height)
    }
}

/// Seconds per phase.
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
    pub seconds: PhaseSeconds,
    pub selection_seconds: crate::damage::select::SelectTimes,
    pub gaussians_before: usize,
    pub gaussians_after: usize,
    pub ms_per_refine_step: f64,
    /// The refinement step by stage.
    pub stage_ms_per_step: crate::train::trainer::StageTimes,
    /// A full-image step of the same model at the same resolution, for comparison.
    pub ms_per_full_step: f64,
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

pub(super) fn phase_progress(
    ctx: &JobContext,
    phase: &'static str,
    step: usize,
    total: usize,
    n: usize,
) {
    ctx.progress(Progress {
        phase,
        step: step as u32,
        total: total as u32,
        loss: f32::NAN,
        psnr: None,
        gaussians: n,
        elapsed: std::time::Duration::ZERO,
        eta: std::time::Duration::ZERO,
    });
}

/// The whole refinement, in the calling job.
pub fn refine(
    ctx: &mut JobContext,
    dataset: &Dataset,
    model: &Splats,
    config: &RefineConfig,
) -> Result<RefineOutcome, JobError> {
    refine_from(ctx, dataset, model, model, config)
}

/// `refine` of `model`, scored before against `baseline`: the twin as it was, when the caller
/// added Gaussians to it for the refinement to train (the update's new-damage seeds).
pub fn refine_from(
    ctx: &mut JobContext,
    dataset: &Dataset,
    baseline: &Splats,
    model: &Splats,
    config: &RefineConfig,
) -> Result<RefineOutcome, JobError> {
    let started = Instant::now();
    let mut seconds = PhaseSeconds::default();
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
    let t = Instant::now();
    let selection = match &config.given {
        Some(given) => given_selection(model, given),
        None => select_by_masks(ctx, dataset, model, config, &train_idx, masks.as_ref())?,
    };
    let n = model.len();
    seconds.select = t.elapsed().as_secs_f64();
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
    let t = Instant::now();
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
    let settings = RenderSettings::new(config.background, model.sh_degree);
    let mut lift = WeightLift::new(model, 1, settings);
    let mut views = Vec::with_capacity(all.len());
    for (done, &(index, heldout)) in all.iter().enumerate() {
        let camera = dataset.view_camera(index, config.scale)?;
        let weights = lift.view(&camera, |_, _| 1.0);
        // Visible: draws at least a tenth of a pixel's worth in this view.
        let visible: Vec<bool> = weights.iter().map(|&w| w > 0.1).collect();
        let projected = lift.projected();
        let k = camera.intrinsics;
        let hulls = view_hulls(
            projected,
            &visible,
            &selection.selected,
            &region_of,
            &config.hulls,
            k.width,
            k.height,
        );
        let pixels = union_mask(&hulls, k.width, k.height).count();
        views.push(ViewHulls {
            view: dataset.views[index].name.clone(),
            index,
            heldout,
            width: k.width,
            height: k.height,
            hull_count: hulls.len(),
            hulls,
            pixels,
        });
        phase_progress(ctx, "hulls", done + 1, all.len(), n);
    }
    drop(lift);
    seconds.hulls = t.elapsed().as_secs_f64();

    // 3. The crops of the training views' hulls, at the refinement scale.
    let t = Instant::now();
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
    let crops: Vec<TrainView> = trained
        .par_iter()
        .map(|v| {
            let mut loaded = load_views(dataset, &[v.index], config.scale, mode.uses_masks())?;
            to_twin_look(&mut loaded, &[v.index], config);
            apply_mode(&mut loaded, mode, &config.select.palette);
            let full = loaded.pop().expect("one view loaded");
            Ok(hull_view(&full, &v.hulls, config.crop_margin_px))
        })
        .collect::<Result<_, crate::scene::SceneError>>()?;
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
    seconds.load = t.elapsed().as_secs_f64();

    // 4. Train the selection.
    let t = Instant::now();
    let mut spec = refine_spec(config, model, labels);
    spec.trainable = Some(selection.mask(n));
    if let Some(rate) = config.neighbour_geometry_rate {
        let mut rates = vec![rate; n];
        for &g in &selection.validated {
            rates[g as usize] = 1.0;
        }
        spec.geometry_rate = Some(rates);
    }
    // A full-image step of the same run, for the cost comparison: a few steps on uncropped views.
    let full_step_ms = full_step_ms(dataset, model, &spec, &trained, config, mode)?;
    let setup = TrainSetup {
        spec,
        splats: model.clone(),
        views: crops.clone(),
        heldout: Vec::new(),
    };
    let outcome = run_training(ctx, setup, "refine")?;
    seconds.refine = t.elapsed().as_secs_f64();
    let mut refined = (*outcome.splats).clone();
    mark_refined(&mut refined, model, &selection);

    // 5. Score before and after on the held-out views.
    let t = Instant::now();
    let readout = DamageReadout {
        mode,
        ..DamageReadout::for_model(baseline, config.select.palette)
    };
    let heldout: Vec<&ViewHulls> = views.iter().filter(|v| v.heldout).collect();
    let before = quality(dataset, baseline, &heldout, config, &readout)?;
    let after = quality(dataset, &refined, &heldout, config, &readout)?;
    seconds.evaluate = t.elapsed().as_secs_f64();
    seconds.total = started.elapsed().as_secs_f64();

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
        seconds,
        selection_seconds: selection.seconds,
        gaussians_before: baseline.len(),
        gaussians_after: refined.len(),
        ms_per_refine_step: outcome.timings.total * 1000.0 / outcome.steps.max(1) as f64,
        ms_per_full_step: full_step_ms,
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

/// The training view of one view's hulls: the box around all of them plus a margin, cropped
/// from the full view, with their union (in crop coordinates) as the loss region. The trainer
/// renders only the tiles that region needs, so the step costs what the hulls cost.
fn hull_view(full: &TrainView, hulls: &[Hull], margin: u32) -> TrainView {
    let k = full.camera.intrinsics;
    let (mut x0, mut y0, mut x1, mut y1) = (k.width, k.height, 0, 0);
    for hull in hulls {
        x0 = x0.min(hull.x0);
        y0 = y0.min(hull.y0);
        x1 = x1.max(hull.x0 + hull.mask.width);
        y1 = y1.max(hull.y0 + hull.mask.height);
    }
    let (x0, y0) = (x0.saturating_sub(margin), y0.saturating_sub(margin));
    let (x1, y1) = ((x1 + margin).min(k.width), (y1 + margin).min(k.height));
    let (w, h) = (x1.saturating_sub(x0).max(1), y1.saturating_sub(y0).max(1));
    let mut region = union_mask(hulls, k.width, k.height).crop(x0, y0, w, h);
    // Inside the hulls, the view's ignored pixels stay ignored.
    if let Some(used) = &full.region {
        let used = used.crop(x0, y0, w, h);
        for (r, u) in region.data.iter_mut().zip(&used.data) {
            *r &= u;
        }
    }
    TrainView {
        name: full.name.clone(),
        camera: full.camera.cropped(x0, y0, w, h),
        image: full.image.crop(x0, y0, w, h),
        labels: full.labels.iter().map(|m| m.crop(x0, y0, w, h)).collect(),
        region: Some(region),
    }
}

/// The refinement's training spec (its trainable mask is set by the caller).
fn refine_spec(config: &RefineConfig, model: &Splats, labels: bool) -> TrainSpec {
    let iterations = config.iterations.max(1);
    let mut spec = TrainSpec::reconstruction(iterations);
    spec.sh_degree = model.sh_degree;
    // The model is trained: every SH band is rendered from the first step.
    spec.sh_ramp_every = 0;
    spec.seed = config.seed;
    spec.background = config.background;
    spec.eval_every = 0;
    spec.targets.label_weight = if labels && model.label_channels > 0 {
        config.label_weight
    } else {
        0.0
    };
    spec.targets.label_pos_weight = config.label_pos_weight;
    spec.targets.label_geometry_steps =
        crate::damage::setup::geometry_steps(config.label_geometry_until, iterations);
    spec.lr = config.lr;
    spec.lr.raw_labels = config.label_lr.or(config.lr.raw_labels);
    spec.max_scale_growth = config.max_scale_growth;
    spec.backend = config.backend;
    spec.densify = match config.strategy {
        Strategy::Finetune => DensifyPolicy::Off,
        // No opacity reset: in a short local run it would blank the damage mid-way, and the
        // frozen rest of the twin keeps floaters out anyway.
        Strategy::Retrain => DensifyPolicy::Adaptive(DensifyConfig {
            opacity_reset_every: 0,
            ..densify_for_iterations(iterations, config.seed)
        }),
    };
    spec
}

/// Maps the photos of `views` (dataset indices `indices`) into the twin's light.
pub(super) fn to_twin_look(views: &mut [TrainView], indices: &[usize], config: &RefineConfig) {
    for (view, index) in views.iter_mut().zip(indices) {
        if let Some(transform) = config.appearance.get(index) {
            transform.undo(&mut view.image);
        }
    }
}

/// Gaussians the refinement trained (the selection) or created, marked `REFINED`.
fn mark_refined(refined: &mut Splats, input: &Splats, selection: &Selection) {
    let first_new_id = input.meta.next_id();
    let selected: std::collections::HashSet<u64> = selection
        .selected
        .iter()
        .map(|&g| input.meta.ids[g as usize])
        .collect();
    for g in 0..refined.len() {
        let id = refined.meta.ids[g];
        if id >= first_new_id || selected.contains(&id) {
            refined.meta.state[g] |= state::REFINED;
        }
    }
}
