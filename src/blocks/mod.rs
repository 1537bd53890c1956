//! Twins of long structures trained block by block: "partition → one job per block → merge".
//! A plan (`plan`) cuts a posed dataset into blocks along its long axis with margins and gives
//! each block the photos that see it (`partition`, drawn from above by `picture`); each block
//! trains as an independent job through the focused-run seam (`block_run`: its photos, its
//! Gaussians, its region), its result committed atomically into the plan folder, the shared
//! directory; the engines that run the jobs are Slurm, Kubernetes or local processes, for which
//! `engines` writes the job files; `merge` keeps each block's Gaussians inside its own box and
//! `seam` scores the merged model in a band around each boundary against the rest
//! (docs/CLUSTER.md).

pub mod block_run;
pub mod context_run;
pub mod engines;
pub mod merge;
pub mod partition;
pub mod picture;
pub mod plan;
pub mod region;
pub mod seam;
pub mod surface;

use std::path::Path;

use serde::Serialize;

use crate::scene::SceneError;
use crate::scene::atomic::write_atomic;

pub use plan::{Plan, load_plan, plan_file, plan_folder, save_plan};

/// One block's manifest (`block-KKK/manifest.json`): what its job trains, for people and tools
/// that look at one block; `train-block` reads the plan itself.
#[derive(Serialize)]
struct Manifest<'a> {
    block: usize,
    plan_digest: String,
    dataset: &'a Path,
    /// Kept part and enlarged box along the long axis.
    keeps: [f32; 2],
    trains_on: [f32; 2],
    steps: u32,
    photos: &'a [String],
    skipped: &'a Option<String>,
}

/// Writes `plan` into `folder` (created): `plan.json` and every block's manifest.
pub fn write_plan_folder(folder: &Path, plan: &Plan) -> Result<(), SceneError> {
    std::fs::create_dir_all(folder).map_err(|e| SceneError::io(folder, e))?;
    save_plan(folder, plan)?;
    let digest = plan.digest();
    for (k, block) in plan.blocks.iter().enumerate() {
        let dir = block_run::block_folder(folder, k);
        std::fs::create_dir_all(&dir).map_err(|e| SceneError::io(&dir, e))?;
        let manifest = Manifest {
            block: k,
            plan_digest: digest.clone(),
            dataset: &plan.dataset,
            keeps: [block.start, block.end],
            trains_on: [block.start - plan.margin, block.end + plan.margin],
            steps: plan.training.steps_for(block.photos.len()),
            photos: &block.photos,
            skipped: &block.skipped,
        };
        let path = dir.join("manifest.json");
        let text = serde_json::to_string_pretty(&manifest)
            .map_err(|e| SceneError::invalid(&path, e.to_string()))?;
        write_atomic(&path, |w| std::io::Write::write_all(w, text.as_bytes()))?;
    }
    Ok(())
}
