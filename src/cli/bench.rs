//! `damage-twin bench DATASET`: trains for a fixed number of steps and prints, as JSON, the time
//! per iteration by stage, the Gaussian count, peak memory and bytes per Gaussian. The run is
//! prepared exactly as `train` prepares it (`damage::bench`). With `--refine MODEL`, the cost
//! of a refinement step of that twin against a full-image step instead (`bench_refine`).

use std::path::PathBuf;
use std::sync::Arc;

use damage_twin::damage::bench::bench_job;
use damage_twin::train::job::JobOptions;

use super::args::{RunArgs, drive, open_dataset};

#[derive(clap::Args, Debug)]
pub struct Args {
    pub dataset: PathBuf,
    #[arg(long, default_value_t = 500)]
    pub iters: u32,
    #[command(flatten)]
    pub run: RunArgs,
    // Not `JobArgs`: a benchmark draws no progress bar (it would take time from what it
    // measures), so it has no `--quiet`.
    /// Training threads (default: all cores, or RAYON_NUM_THREADS).
    #[arg(long, value_parser = crate::cli::args::parse_threads)]
    pub threads: Option<usize>,
    /// Time a fine-tune step of this coarse twin (selection, hulls and crops as `refine`
    /// makes them at `--scale`) against a full-image step, interleaved, by stage.
    #[arg(long)]
    pub refine: Option<PathBuf>,
    /// With `--refine`: timed rounds (one step per view of each kind).
    #[arg(long, default_value_t = 3)]
    pub rounds: u32,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(model) = &args.refine {
        return super::bench_refine::run(model, &args);
    }
    let dataset = Arc::new(open_dataset(&args.dataset, args.run.images.background)?);
    let config = args.run.config(args.iters);
    let job = bench_job(dataset, config, JobOptions::headless(args.threads));
    let report = drive(job, "benchmark", true, |_| {})?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
