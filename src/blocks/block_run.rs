//! One block, one job: block K of a plan trained through the focused-run seam (`train::focus`):
//! only its photos, loaded in the model's light, only the Gaussians of its enlarged box (the
//! dataset's initial model cut to the box, all of them trainable), and only its region of each
//! photo (each view cropped to the hull of those Gaussians, which is also the loss region, less
//! the pixels where the sparse points show the rest of the structure in front: `region`; so the
//! rest of the structure seen past the block neither trains it nor costs a step). The
//! result goes into the plan folder as a run folder (`scene::run_folder`): a kill leaves no
//! result or a whole one, and the next run cleans what the dead one left.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::blocks::context_run::{context_model_path, read_context};
use crate::blocks::merge::append_where;
use crate::blocks::plan::Plan;
use crate::blocks::region::{block_pixels, inside_block};
use crate::damage::Palette;
use crate::damage::setup::{RunConfig, apply_mode, effective_mode, model_and_spec, run_spec};
use crate::scene::run_folder::RunFolder;
use crate::scene::{Dataset, SceneError};
use crate::splats::Splats;
use crate::train::focus::hulls::HullConfig;
use crate::train::focus::{Focus, ViewLights, continue_trained, crop_to_hulls};
use crate::train::job::{JobContext, JobError};
use crate::train::run::{TrainSetup, run_training};
use crate::train::spec::TrainView;

/// The files a block's result folder holds; none is carried over from an earlier run.
pub const BLOCK_OUTPUTS: &[&str] = &["model.ply", "block.json"];
/// Pixels of context kept around a block's hull in each crop.
const CROP_MARGIN_PX: u32 = 16;

/// The folder of block `k` in a plan folder (its manifest, and its `result/`).
pub fn block_folder(plan_dir: &Path, k: usize) -> PathBuf {
    plan_dir.join(format!("block-{k:03}"))
}

/// The run folder block `k`'s result is committed to.
pub fn result_folder(plan_dir: &Path, k: usize) -> PathBuf {
    block_folder(plan_dir, k).join("result")
}

/// What a block's run records beside its model (`block.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BlockRecord {
    /// The digest of the plan it was trained for (`Plan::digest`).
    pub plan_digest: String,
    pub block: usize,
    pub photos: usize,
    pub steps: u32,
    /// The Gaussians it started from: the context's in its box, or the initial points' (None:
    /// a record written before this was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial_gaussians: Option<usize>,
    pub gaussians: usize,
    pub seconds: f64,
    /// The share of the photos' pixels inside the block's hull (what a step renders).
    pub region_fraction: f64,
    /// Peak resident memory of the process that trained it (None where not measured).
    pub peak_rss_mb: Option<f64>,
    /// The context Gaussians it rendered frozen (None: trained without a context).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub context_gaussians: Option<usize>,
}

/// The record of block `k`'s result when it is finished for this plan (its model beside it):
/// rerunning it is then a no-op.
pub fn finished(plan_dir: &Path, plan: &Plan, k: usize) -> Option<BlockRecord> {
    let record: BlockRecord = committed_record(&result_folder(plan_dir, k), "block.json")?;
    (record.plan_digest == plan.digest() && record.block == k).then_some(record)
}

/// The record `record_file` of a committed run folder (`commit_model`) when it reads and its
/// `model.ply` is beside it; `None` otherwise (not run, or what a killed run left).
pub(crate) fn committed_record<R: serde::de::DeserializeOwned>(
    folder: &Path,
    record_file: &str,
) -> Option<R> {
    let text = std::fs::read_to_string(folder.join(record_file)).ok()?;
    let record = serde_json::from_str(&text).ok()?;
    folder.join("model.ply").is_file().then_some(record)
}

/// A trained block.
pub struct BlockOutcome {
    /// The block's own Gaussians (what its `model.ply` holds).
    pub splats: Arc<Splats>,
    /// The context Gaussians it rendered frozen, as the run left them (None: no context).
    pub context: Option<Splats>,
    pub record: BlockRecord,
    pub cancelled: bool,
}

/// Trains block `k` of `plan` (loaded from the folder `plan_dir`, where a context's result is
/// read from) on `dataset` (the plan's dataset, opened).
pub fn train_block(
    ctx: &mut JobContext,
    dataset: &Dataset,
    plan: &Plan,
    plan_dir: &Path,
    k: usize,
) -> Result<BlockOutcome, JobError> {
    let started = Instant::now();
    let block = plan.blocks.get(k).ok_or_else(|| {
        JobError::Invalid(format!(
            "block {k} is out of range: the plan has blocks 0 to {}",
            plan.blocks.len() - 1
        ))
    })?;
    if let Some(why) = &block.skipped {
        return Err(JobError::Invalid(format!("block {k} is skipped: {why}")));
    }
    // The context first: a block of a plan whose context has not finished fails before it
    // loads anything.
    let context = match &plan.context {
        Some(_) => Some(read_context(plan_dir, plan)?),
        None => None,
    };
    let indices = block
        .photos
        .iter()
        .map(|name| {
            dataset.view_index(name).ok_or_else(|| {
                JobError::Invalid(format!(
                    "block {k}'s photo {name} is not in {}",
                    dataset.root.display()
                ))
            })
        })
        .collect::<Result<Vec<usize>, JobError>>()?;
    let training = &plan.training;
    let scale = training
        .image_scale()
        .ok_or_else(|| JobError::Invalid(format!("bad scale {:?}", training.scale)))?;
    let steps = training.steps_for(indices.len());
    let config = run_config(dataset, plan, scale, steps);
    let lights = ViewLights::new();
    let focus = Focus {
        dataset,
        scale,
        lights: &lights,
        margin_px: CROP_MARGIN_PX,
    };
    let views = load_photos(&focus, &config, &indices)?;
    let mode = config.mode;

    // Its Gaussians, every one trainable: with a context, the context's inside the enlarged box,
    // a trained start (docs/CLUSTER.md, "Blocks start from the context"); without, the initial
    // model cut to the box.
    let (mut splats, mut spec) = match &context {
        // The initial model is not loaded: the context's Gaussians replace it.
        Some(context) => {
            let mut spec = run_spec(&config, mode);
            continue_trained(&mut spec);
            (context.clone(), spec)
        }
        None => model_and_spec(dataset, &views, &config, mode)?,
    };
    let keep: Vec<bool> = splats
        .means
        .iter()
        .map(|&p| plan.trains_point(k, plan.frame.coordinates(p)))
        .collect();
    splats.retain(&keep);
    let initial_gaussians = splats.len();
    if splats.is_empty() {
        return Err(JobError::Invalid(format!(
            "block {k}: no initial Gaussian lies in its box"
        )));
    }
    ctx.log(format!(
        "block {k}: {} photos, {} initial Gaussians, {steps} steps",
        indices.len(),
        splats.len()
    ));

    // Its region: each view cropped to the hull of the block's Gaussians.
    let all: Vec<u32> = (0..splats.len() as u32).collect();
    let regions = vec![0; all.len()];
    let hull_config = HullConfig {
        per_region: false,
        ..HullConfig::default()
    };
    let placed: Vec<(usize, bool)> = indices.iter().map(|&i| (i, false)).collect();
    let hulls = focus.draw_hulls(
        &splats,
        &all,
        &regions,
        &placed,
        &hull_config,
        config.background,
        &mut |_, _| {},
    )?;
    let mut crops = Vec::new();
    let mut region_pixels = 0.0;
    // Where the sparse points show the rest of the structure in front, the photo is not the
    // block's to explain (`region`).
    let points: Vec<glam::Vec3> = dataset
        .points
        .as_ref()
        .map(|p| p.positions.clone())
        .unwrap_or_default();
    let inside = inside_block(plan, k, &points);
    // Each full photo is consumed as its crop is made, so the photos are in memory once: kept
    // whole beside their crops until the end, a block's photos took 1.5 times the memory the
    // whole run's took per photo (docs/CLUSTER.md, "Peak memory").
    for (mut view, hull) in views.into_iter().zip(&hulls) {
        if hull.hulls.is_empty() {
            continue;
        }
        let mut owned = block_pixels(&view.camera, &points, &inside);
        if let Some(used) = &view.region {
            for (o, u) in owned.data.iter_mut().zip(&used.data) {
                *o &= u;
            }
        }
        view.region = Some(owned);
        let crop = crop_to_hulls(&view, &hull.hulls, CROP_MARGIN_PX);
        let trained = crop.region.as_ref().map_or(0, |r| r.count());
        region_pixels += trained as f64 / (hull.width as f64 * hull.height as f64);
        crops.push(crop);
    }
    if crops.is_empty() {
        return Err(JobError::Invalid(format!(
            "block {k}: its Gaussians are visible in none of its photos"
        )));
    }
    let region_fraction = region_pixels / crops.len() as f64;
    drop(hulls);
    spec.iterations = steps;
    // With a context, the context's Gaussians outside the block's box render frozen behind and
    // around its own: its photos' sky and the rest of the scene are explained, and only its own
    // Gaussians learn.
    let frozen = match context {
        Some(context) => Some(add_frozen_context(
            &mut splats,
            &mut spec,
            plan,
            k,
            &context,
            &context_model_path(plan_dir),
        )?),
        None => None,
    };
    let outcome = run_training(
        ctx,
        TrainSetup {
            spec,
            splats,
            views: crops,
            heldout: Vec::new(),
        },
        "block",
    )?;
    let (splats, context) = match frozen {
        Some(ids) => {
            let (own, context) = split_ids(&outcome.splats, ids);
            (Arc::new(own), Some(context))
        }
        None => (outcome.splats, None),
    };
    let record = BlockRecord {
        plan_digest: plan.digest(),
        block: k,
        photos: indices.len(),
        steps: outcome.steps,
        gaussians: splats.len(),
        seconds: started.elapsed().as_secs_f64(),
        region_fraction,
        peak_rss_mb: None,
        initial_gaussians: Some(initial_gaussians),
        context_gaussians: context.as_ref().map(Splats::len),
    };
    Ok(BlockOutcome {
        splats,
        context,
        record,
        cancelled: outcome.cancelled,
    })
}

/// The run settings of a plan's job at `scale` for `steps` steps.
pub(crate) fn run_config(
    dataset: &Dataset,
    plan: &Plan,
    scale: crate::scene::ImageScale,
    steps: u32,
) -> RunConfig {
    let training = &plan.training;
    RunConfig {
        mode: effective_mode(dataset, training.mode),
        scale,
        iterations: steps,
        sh_degree: training.sh_degree,
        seed: training.seed,
        background: glam::Vec3::from_array(training.background),
        ..RunConfig::default()
    }
}

/// The photos `indices` in the model's light (no survey light here), as targets of the mode.
pub(crate) fn load_photos(
    focus: &Focus,
    config: &RunConfig,
    indices: &[usize],
) -> Result<Vec<TrainView>, JobError> {
    let mode = config.mode;
    let palette = Palette::default();
    let targets = move |views: &mut [TrainView]| apply_mode(views, mode, &palette);
    Ok(focus.load(indices, mode.uses_masks(), &targets)?)
}

/// Appends to `splats` (block `k`'s own Gaussians, all trainable) the `context`'s Gaussians
/// (read from `source`) that lie outside the block's box, frozen (`spec.trainable`), with ids
/// after the block's own. Returns the range of ids they were given.
fn add_frozen_context(
    splats: &mut Splats,
    spec: &mut crate::train::spec::TrainSpec,
    plan: &Plan,
    k: usize,
    context: &Splats,
    source: &Path,
) -> Result<std::ops::Range<u64>, JobError> {
    let own = splats.len();
    let first = splats.meta.next_id();
    let mut into = Some(std::mem::take(splats));
    append_where(&mut into, context, source, |p| {
        !plan.trains_point(k, plan.frame.coordinates(p))
    })?;
    *splats = into.unwrap_or_default();
    for (i, id) in splats.meta.ids.iter_mut().enumerate().skip(own) {
        *id = first + (i - own) as u64;
    }
    let mut trainable = vec![true; splats.len()];
    trainable[own..].fill(false);
    spec.trainable = Some(trainable);
    Ok(first..first + (splats.len() - own) as u64)
}

/// `splats` split into the Gaussians whose ids lie outside `ids` and those inside.
fn split_ids(splats: &Splats, ids: std::ops::Range<u64>) -> (Splats, Splats) {
    let inside: Vec<bool> = splats.meta.ids.iter().map(|id| ids.contains(id)).collect();
    let mut context = splats.clone();
    context.retain(&inside);
    let mut own = splats.clone();
    own.retain(&inside.iter().map(|&i| !i).collect::<Vec<bool>>());
    (own, context)
}

/// Begins block `k`'s result folder: what dead runs left beside it is removed, and an
/// unwritable plan folder fails now, before the training.
pub fn begin_result(plan_dir: &Path, k: usize) -> Result<RunFolder, SceneError> {
    RunFolder::begin(&result_folder(plan_dir, k), BLOCK_OUTPUTS)
}

/// Writes a trained block into its begun result folder and puts it in place, the model first
/// and the record last (a record always describes the model beside it).
pub fn commit_result(folder: RunFolder, outcome: &BlockOutcome) -> Result<(), SceneError> {
    commit_model(folder, &outcome.splats, "block.json", &outcome.record)
}

/// Writes `model.ply` and then the record `record_file` into a begun run folder and puts it in
/// place (a record always describes the model beside it).
pub(crate) fn commit_model(
    folder: RunFolder,
    splats: &Splats,
    record_file: &str,
    record: &impl Serialize,
) -> Result<(), SceneError> {
    crate::splats::ply::write_splats(&folder.path("model.ply"), splats)?;
    let path = folder.path(record_file);
    let text = serde_json::to_string_pretty(record)
        .map_err(|e| SceneError::invalid(&path, e.to_string()))?;
    crate::scene::atomic::write_atomic(&path, |w| std::io::Write::write_all(w, text.as_bytes()))?;
    folder.commit()
}
