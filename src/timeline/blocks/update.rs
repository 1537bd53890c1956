//! `twin update` on a partitioned twin: the survey's plan is the previous survey's plan with its
//! cuts, margins and training settings, each block given the new survey's photos (`replan`);
//! every block that did not change is marked skipped in it ("kept from `previous`'s model"), so
//! every engine (`cluster local|slurm|k8s`, `train-block`) trains only the changed blocks. The
//! merge then keeps, per block, either its new result inside its own box or the previous
//! model's Gaussians inside that box, exactly as they were.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::blocks::block_run::{finished, result_folder};
use crate::blocks::merge::{MergedBlock, keep_block};
use crate::blocks::partition::{DEFAULT_MIN_SHARE, replan};
use crate::blocks::{Plan, load_plan, plan_file, write_plan_folder};
use crate::scene::files::read_text;
use crate::splats::Splats;
use crate::timeline::blocks::changed::BlockChanges;
use crate::timeline::blocks::{BLOCKS_FILE, BLOCKS_FORMAT, SurveyBlocks, load_survey_blocks};
use crate::timeline::detect_survey::{CHANGES_FILE, compared_survey};
use crate::timeline::twin::{HISTORY_FILE, TimelineError, Twin};
use crate::timeline::update::tag_damage;

/// The folder inside a project holding the plans of its block updates (`blocks/<survey>/`).
pub const PLANS_DIR: &str = "blocks";
/// Largest `changes.json` read for its blocks.
const MAX_CHANGES_BYTES: u64 = 64 << 20;

/// A block update being prepared or run: the survey's plan and which blocks it trains.
#[derive(Clone, Debug)]
pub struct BlockUpdate {
    pub survey: String,
    /// The survey whose model the unchanged blocks are kept from.
    pub previous: String,
    /// The survey's plan folder (absolute; the engines' shared directory).
    pub plan_dir: PathBuf,
    pub plan: Plan,
    /// Blocks trained on the survey's photos.
    pub trained: Vec<usize>,
    /// Blocks kept from the previous model.
    pub kept: Vec<usize>,
}

/// What a block update records as the survey's metrics.
#[derive(Clone, Debug, Serialize)]
pub struct BlockUpdateReport {
    pub survey: String,
    pub previous: String,
    pub plan: PathBuf,
    pub trained: Vec<usize>,
    pub kept: Vec<usize>,
    pub gaussians: usize,
    /// Damage Gaussians first seen in this survey (the trained blocks' damage).
    pub new_damage_gaussians: usize,
    pub blocks: Vec<MergedBlock>,
}

fn io(path: &Path, message: impl std::fmt::Display) -> TimelineError {
    TimelineError::Io {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// The survey before `name` that has a model, and its block record when that model was merged
/// from blocks (None: not a partitioned twin, `timeline::update` updates it).
pub fn partitioned_previous(
    twin: &Twin,
    name: &str,
) -> Result<Option<(String, SurveyBlocks)>, TimelineError> {
    let index = twin.survey_index(name)?;
    let Some(previous) = compared_survey(twin, index) else {
        return Ok(None);
    };
    Ok(load_survey_blocks(twin, &previous)?.map(|record| (previous, record)))
}

/// The blocks `twin detect` found changed in survey `name` (at least `min_pixels` changed
/// pixels each), read from its `changes.json`; an error when it was not detected, or against
/// another survey than `previous`.
pub fn detected_changed_blocks(
    twin: &Twin,
    name: &str,
    previous: &str,
    min_pixels: u64,
) -> Result<Vec<usize>, TimelineError> {
    #[derive(Deserialize)]
    struct Detected {
        twin_of: String,
        blocks: Option<BlockChanges>,
    }
    let survey = twin.survey(name)?;
    let Some(folder) = &survey.changes else {
        return Err(io(
            &twin.file(),
            format!(
                "survey `{name}` has no detected changes: run `twin detect --survey {name}` first (or name the blocks with --blocks)"
            ),
        ));
    };
    let path = twin.inside(folder)?.join(CHANGES_FILE);
    let text = read_text(&path, MAX_CHANGES_BYTES)?;
    let detected: Detected =
        serde_json::from_str(&text).map_err(|e| io(&path, format!("not a change summary: {e}")))?;
    if detected.twin_of != previous {
        return Err(io(
            &path,
            format!(
                "detected against survey `{}`, not `{previous}`: run `twin detect --survey {name}` again",
                detected.twin_of
            ),
        ));
    }
    let blocks = detected.blocks.ok_or_else(|| {
        io(
            &path,
            "holds no changes per block: run `twin detect` again (it attributes them on a partitioned twin)",
        )
    })?;
    Ok(blocks.changed(min_pixels))
}

/// Prepares survey `name`'s block update retraining `changed` (block indices of the previous
/// plan): writes its plan folder (`PLANS_DIR/<name>/`, left as it is when it already holds
/// this very plan, so a rerun keeps the blocks it trained).
pub fn prepare_block_update(
    twin: &Twin,
    name: &str,
    changed: &[usize],
) -> Result<BlockUpdate, TimelineError> {
    let (previous, record) = partitioned_previous(twin, name)?.ok_or_else(|| {
        io(
            &twin.file(),
            format!("the model before survey `{name}` was not merged from blocks"),
        )
    })?;
    let survey = twin.survey(name)?;
    if survey.alignment.is_some() || survey.views.is_some() {
        return Err(io(
            &twin.file(),
            format!(
                "survey `{name}` is placed by an alignment or shares a joint model: a block update needs a dataset posed in the twin's frame"
            ),
        ));
    }
    let previous_plan = load_plan(&record.plan)?;
    if let Some(&k) = changed.iter().find(|&&k| k >= previous_plan.blocks.len()) {
        return Err(io(
            &plan_file(&record.plan),
            format!(
                "block {k} is not in the plan ({} blocks)",
                previous_plan.blocks.len()
            ),
        ));
    }
    let dataset = twin.open_survey_dataset(name)?;
    let dataset_path =
        std::fs::canonicalize(twin.resolve(&survey.dataset)).map_err(|e| io(&survey.dataset, e))?;
    let mut plan = replan(&previous_plan, &dataset, &dataset_path, DEFAULT_MIN_SHARE)
        .map_err(|e| io(&dataset_path, e))?;
    for (k, block) in plan.blocks.iter_mut().enumerate() {
        if !changed.contains(&k) {
            block.skipped = Some(format!(
                "unchanged since survey `{previous}`: kept from its model"
            ));
        }
    }
    let project = std::fs::canonicalize(twin.dir()).map_err(|e| io(twin.dir(), e))?;
    let plan_dir = project.join(PLANS_DIR).join(name);
    let same = load_plan(&plan_dir).is_ok_and(|p| p.digest() == plan.digest());
    if !same {
        write_plan_folder(&plan_dir, &plan)?;
    }
    let (trained, kept) = (0..plan.blocks.len()).partition(|&k| plan.blocks[k].skipped.is_none());
    Ok(BlockUpdate {
        survey: name.to_string(),
        previous,
        plan_dir,
        plan,
        trained,
        kept,
    })
}

/// The blocks of `update` still to train (not finished for its plan).
pub fn unfinished(update: &BlockUpdate) -> Vec<usize> {
    update
        .trained
        .iter()
        .copied()
        .filter(|&k| finished(&update.plan_dir, &update.plan, k).is_none())
        .collect()
}

/// The updated model: each trained block's result and each kept block's part of the previous
/// model, inside its own box; the trained blocks' damage is tagged as first seen in this survey.
/// A trained block without a finished result is an error naming it.
pub fn merge_block_update(
    twin: &Twin,
    update: &BlockUpdate,
) -> Result<(Splats, BlockUpdateReport), TimelineError> {
    let previous = twin.load_model(&update.previous)?.ok_or_else(|| {
        io(
            &twin.file(),
            format!("survey `{}` has no model", update.previous),
        )
    })?;
    let previous_path = twin
        .model_path(&update.previous)?
        .unwrap_or_else(|| twin.file());
    let mut merged: Option<Splats> = None;
    let mut blocks = Vec::new();
    for k in 0..update.plan.blocks.len() {
        let (part, path) = if update.trained.contains(&k) {
            let folder = result_folder(&update.plan_dir, k);
            if finished(&update.plan_dir, &update.plan, k).is_none() {
                return Err(io(
                    &folder,
                    format!(
                        "block {k} has no finished result for this update's plan: train it (rerun `twin update`, or the engine's jobs)"
                    ),
                ));
            }
            let path = folder.join("model.ply");
            (crate::splats::ply::read_splats(&path)?, path)
        } else {
            (previous.clone(), previous_path.clone())
        };
        let kept = keep_block(&mut merged, &update.plan, k, &part, &path)?;
        let trained = update.trained.contains(&k);
        blocks.push(MergedBlock {
            block: k,
            trained: if trained { part.len() } else { 0 },
            kept,
            skipped: update.plan.blocks[k].skipped.clone(),
        });
    }
    let mut merged = merged.filter(|m| !m.is_empty()).ok_or_else(|| {
        io(
            &update.plan_dir,
            "no block kept any Gaussian: nothing to merge",
        )
    })?;
    let index = twin.survey_index(&update.survey)?;
    let new_damage = tag_damage(&mut merged, index as u16);
    let report = BlockUpdateReport {
        survey: update.survey.clone(),
        previous: update.previous.clone(),
        plan: update.plan_dir.clone(),
        trained: update.trained.clone(),
        kept: update.kept.clone(),
        gaussians: merged.len(),
        new_damage_gaussians: new_damage,
        blocks,
    };
    Ok((merged, report))
}

/// Records a block update as one commit: the survey's model, its metrics (`report`) and its
/// block record; no training history (a previous one is removed). Returns the model's path.
pub fn commit_block_update(
    twin: &mut Twin,
    update: &BlockUpdate,
    splats: &Splats,
    report: &BlockUpdateReport,
) -> Result<PathBuf, TimelineError> {
    let record = SurveyBlocks {
        format: BLOCKS_FORMAT.into(),
        plan: update.plan_dir.clone(),
        plan_digest: update.plan.digest(),
        previous: Some(update.previous.clone()),
        trained: update.trained.clone(),
        kept: update.kept.clone(),
    };
    let name = update.survey.as_str();
    twin.commit(|twin| {
        let index = twin.survey_index(name)?;
        let path = twin.save_model(name, splats)?;
        twin.save_metrics(name, report)?;
        twin.write_survey_json(name, BLOCKS_FILE, &record)?;
        twin.replaces(name, HISTORY_FILE)?;
        twin.project.surveys[index].appearance = None;
        Ok(path)
    })
}
