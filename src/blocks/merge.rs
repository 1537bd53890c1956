//! The merge: every trained block's Gaussians inside its own un-enlarged box (VastGaussian's
//! rule: what a block learnt in its margins belongs to its neighbour), put together into one
//! model with fresh ids. The blocks must share the SH degree and label channels (one plan's
//! blocks do).

use std::path::Path;

use glam::Vec3;
use serde::Serialize;

use crate::blocks::block_run::{finished, result_folder};
use crate::blocks::context_run::{context_model_path, read_context};
use crate::blocks::plan::Plan;
use crate::scene::SceneError;
use crate::splats::Splats;

/// What the context gave the merged model: its Gaussians and those outside every block's box.
#[derive(Clone, Debug, Serialize)]
pub struct MergedContext {
    pub trained: usize,
    pub kept: usize,
}

/// A plan's merged model and what each block (and the context) gave it.
pub struct Merged {
    pub splats: Splats,
    pub blocks: Vec<MergedBlock>,
    pub context: Option<MergedContext>,
}

/// What each block gave the merged model.
#[derive(Clone, Debug, Serialize)]
pub struct MergedBlock {
    pub block: usize,
    /// Gaussians the block trained, and those inside its own box that were kept.
    pub trained: usize,
    pub kept: usize,
    pub skipped: Option<String>,
}

/// Reads every block's result in `plan_dir` and keeps each block's Gaussians inside its box, and
/// with a context, the context's Gaussians outside every box.
/// A block neither skipped nor finished for this plan is an error naming it.
pub fn merge_blocks(plan_dir: &Path, plan: &Plan) -> Result<Merged, SceneError> {
    let mut merged: Option<Splats> = None;
    let mut blocks = Vec::new();
    for (k, block) in plan.blocks.iter().enumerate() {
        if let Some(why) = &block.skipped {
            blocks.push(MergedBlock {
                block: k,
                trained: 0,
                kept: 0,
                skipped: Some(why.clone()),
            });
            continue;
        }
        let folder = result_folder(plan_dir, k);
        if finished(plan_dir, plan, k).is_none() {
            return Err(SceneError::invalid(
                &folder,
                format!(
                    "block {k} has no finished result for this plan: run train-block with --block {k}"
                ),
            ));
        }
        let path = folder.join("model.ply");
        let splats = crate::splats::ply::read_splats(&path)?;
        let kept = keep_block(&mut merged, plan, k, &splats, &path)?;
        blocks.push(MergedBlock {
            block: k,
            trained: splats.len(),
            kept,
            skipped: None,
        });
    }
    // The context's Gaussians outside every block's box: the sky and the far ground.
    let context = match plan.context {
        Some(_) => {
            let context = read_context(plan_dir, plan)?;
            let kept = append_where(&mut merged, &context, &context_model_path(plan_dir), |p| {
                plan.outside_every_block(plan.frame.coordinates(p))
            })?;
            Some(MergedContext {
                trained: context.len(),
                kept,
            })
        }
        None => None,
    };
    let merged = merged.filter(|m| !m.is_empty()).ok_or_else(|| {
        SceneError::invalid(plan_dir, "no block kept any Gaussian: nothing to merge")
    })?;
    Ok(Merged {
        splats: merged,
        blocks,
        context,
    })
}

/// Appends to `into` (started from the first part's SH degree and label channels) the Gaussians
/// of `part` (read from `source`) whose centres lie in block `k`'s own box (`Plan::keeps_point`),
/// each with its survey tags and state and a fresh id. Returns how many it kept; a part whose SH
/// degree or label channels differ from `into`'s is an error naming `source`.
pub fn keep_block(
    into: &mut Option<Splats>,
    plan: &Plan,
    k: usize,
    part: &Splats,
    source: &Path,
) -> Result<usize, SceneError> {
    append_where(into, part, source, |p| {
        plan.keeps_point(k, plan.frame.coordinates(p))
    })
}

/// Appends to `into` (started from the first part's SH degree and label channels) the Gaussians
/// of `part` (read from `source`) whose centres `keep` accepts, each with its survey tags and
/// state and a fresh id (its index in `into`). Returns how many it kept.
pub fn append_where(
    into: &mut Option<Splats>,
    part: &Splats,
    source: &Path,
    keep: impl Fn(Vec3) -> bool,
) -> Result<usize, SceneError> {
    let into = into.get_or_insert_with(|| Splats::empty(part.sh_degree, part.label_channels));
    if into.sh_degree != part.sh_degree || into.label_channels != part.label_channels {
        return Err(SceneError::invalid(
            source,
            format!(
                "SH degree {} and {} label channels differ from the other blocks' {} and {}",
                part.sh_degree, part.label_channels, into.sh_degree, into.label_channels
            ),
        ));
    }
    if into.overlay.is_none() {
        into.overlay = part.overlay;
    }
    let mut kept = 0;
    for g in 0..part.len() {
        if !keep(part.means[g]) {
            continue;
        }
        let id = into.len() as u64;
        into.push(
            part.means[g],
            part.log_scales[g],
            part.rotations[g],
            part.raw_opacities[g],
            part.sh_of(g),
            part.labels_of(g),
            id,
            part.meta.survey[g],
        );
        let last = into.len() - 1;
        into.meta.damage_survey[last] = part.meta.damage_survey[g];
        into.meta.state[last] = part.meta.state[g];
        kept += 1;
    }
    Ok(kept)
}
