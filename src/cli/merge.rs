//! `damage-twin merge PLAN --out MODEL`: one model from a plan's trained blocks
//! (`blocks::merge`), with the seam report on the held-out views (`blocks::seam`). MODEL is a
//! folder like `train`'s: `model.ply` (the merged twin) and `merge.json` (what each block gave,
//! the scores), replaced as a whole.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use serde::Serialize;

use damage_twin::blocks::merge::{MergedBlock, MergedContext, merge_blocks};
use damage_twin::blocks::seam::{SeamReport, seam_report};
use damage_twin::blocks::{load_plan, plan_folder};
use damage_twin::scene::atomic::write_atomic;
use damage_twin::scene::run_folder::RunFolder;

use super::args::open_dataset;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The plan folder (or its plan.json).
    pub plan: PathBuf,
    /// Output folder for model.ply and merge.json.
    #[arg(long)]
    pub out: PathBuf,
    /// Skip the seam report (no rendering of the held-out views).
    #[arg(long)]
    pub no_report: bool,
}

#[derive(Serialize)]
struct MergeReport {
    gaussians: usize,
    blocks: Vec<MergedBlock>,
    #[serde(skip_serializing_if = "Option::is_none")]
    context: Option<MergedContext>,
    seam: Option<SeamReport>,
}

/// Merges the plan at `plan_path` into the folder `out`; returns the report's JSON.
pub fn merge(plan_path: &Path, out: &Path, report: bool) -> anyhow::Result<String> {
    let plan = load_plan(plan_path)?;
    let dir = plan_folder(plan_path);
    let outputs = RunFolder::begin(out, &["model.ply", "merge.json"])
        .with_context(|| format!("preparing output folder {}", out.display()))?;
    let damage_twin::blocks::merge::Merged {
        splats: merged,
        blocks,
        context,
    } = merge_blocks(&dir, &plan)?;
    let seam = if report {
        let dataset = open_dataset(
            &plan.dataset,
            glam::Vec3::from_array(plan.training.background),
        )?;
        Some(seam_report(&dataset, &plan, &merged)?)
    } else {
        None
    };
    let report = MergeReport {
        gaussians: merged.len(),
        blocks,
        context,
        seam,
    };
    damage_twin::splats::ply::write_splats(&outputs.path("model.ply"), &merged)
        .with_context(|| format!("writing {}", out.join("model.ply").display()))?;
    let json = serde_json::to_string_pretty(&report)?;
    write_atomic(&outputs.path("merge.json"), |w| {
        w.write_all(json.as_bytes())
    })
    .with_context(|| format!("writing {}", out.join("merge.json").display()))?;
    outputs
        .commit()
        .with_context(|| format!("replacing {}", out.display()))?;
    Ok(json)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    println!("{}", merge(&args.plan, &args.out, !args.no_report)?);
    Ok(())
}
