//! `damage-twin train-block PLAN [--block K]`: trains one block of a plan (`blocks::block_run`)
//! and commits its result into the plan folder. K from `--block`, else from the engine's
//! environment (`blocks::engines::index`). A block already finished for this plan is a no-op;
//! what a killed run left is cleaned when the next one begins.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;

use damage_twin::blocks::block_run::{begin_result, commit_result, finished, train_block};
use damage_twin::blocks::context_run::{
    begin_context, commit_context, context_finished, train_context,
};
use damage_twin::blocks::engines::index::block_index;
use damage_twin::blocks::{Plan, load_plan, plan_file, plan_folder};
use damage_twin::metrics::peak_rss_mb;
use damage_twin::train::job::Job;

use super::args::{JobArgs, drive, open_dataset};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The plan folder (or its plan.json).
    pub plan: PathBuf,
    /// The block to train (default: SLURM_ARRAY_TASK_ID, else SLURM_PROCID, else
    /// JOB_COMPLETION_INDEX).
    #[arg(long, conflicts_with = "context")]
    pub block: Option<usize>,
    /// Train the plan's context (the coarse whole-scene run every block renders frozen; run it
    /// before the blocks) instead of a block.
    #[arg(long)]
    pub context: bool,
    #[command(flatten)]
    pub job: JobArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let plan = load_plan(&args.plan)?;
    let dir = plan_folder(&args.plan);
    if args.context {
        return run_context(plan, &dir, &args.job);
    }
    let k = block_index(args.block, plan.blocks.len(), |name| {
        std::env::var(name).ok()
    })
    .map_err(anyhow::Error::msg)?;
    if let Some(why) = &plan.blocks[k].skipped {
        println!("block {k} is skipped ({why}): nothing to train");
        return Ok(());
    }
    if let Some(record) = finished(&dir, &plan, k) {
        println!(
            "block {k} is already trained for this plan ({} Gaussians, {} steps): nothing to do",
            record.gaussians, record.steps
        );
        return Ok(());
    }
    let folder = begin_result(&dir, k)
        .with_context(|| format!("preparing block {k}'s result in {}", dir.display()))?;
    let dataset = Arc::new(open_dataset(
        &plan.dataset,
        glam::Vec3::from_array(plan.training.background),
    )?);
    let plan = Arc::new(plan);
    let job = {
        let (dataset, plan, dir) = (dataset.clone(), plan.clone(), dir.clone());
        Job::spawn("block", args.job.options(), move |ctx| {
            train_block(ctx, &dataset, &plan, &dir, k)
        })
    };
    let mut outcome = drive(job, "block", args.job.quiet, |_| {})?;
    if outcome.cancelled {
        anyhow::bail!("block {k} was cancelled: no result written");
    }
    outcome.record.peak_rss_mb = peak_rss_mb();
    commit_result(folder, &outcome)
        .with_context(|| format!("writing block {k}'s result into {}", dir.display()))?;
    println!("{}", serde_json::to_string(&outcome.record)?);
    Ok(())
}

/// `train-block PLAN --context`: trains the plan's context into `PLAN/context/result/`, a no-op
/// when it is finished for this plan.
fn run_context(plan: Plan, dir: &Path, job_args: &JobArgs) -> anyhow::Result<()> {
    if plan.context.is_none() {
        anyhow::bail!(
            "{}: the plan has no context (partition --context-iters N makes one)",
            plan_file(dir).display()
        );
    }
    if let Some(record) = context_finished(dir, &plan) {
        println!(
            "the context is already trained for this plan ({} Gaussians, {} steps): nothing to do",
            record.gaussians, record.steps
        );
        return Ok(());
    }
    let folder = begin_context(dir)
        .with_context(|| format!("preparing the context's result in {}", dir.display()))?;
    let dataset = Arc::new(open_dataset(
        &plan.dataset,
        glam::Vec3::from_array(plan.training.background),
    )?);
    let plan = Arc::new(plan);
    let job = {
        let (dataset, plan) = (dataset.clone(), plan.clone());
        Job::spawn("context", job_args.options(), move |ctx| {
            train_context(ctx, &dataset, &plan)
        })
    };
    let mut outcome = drive(job, "context", job_args.quiet, |_| {})?;
    if outcome.cancelled {
        anyhow::bail!("the context was cancelled: no result written");
    }
    outcome.record.peak_rss_mb = peak_rss_mb();
    commit_context(folder, &outcome)
        .with_context(|| format!("writing the context's result into {}", dir.display()))?;
    println!("{}", serde_json::to_string(&outcome.record)?);
    Ok(())
}
