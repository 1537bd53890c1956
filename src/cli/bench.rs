//! `damage-twin bench DATASET`: trains for a fixed number of steps and prints, as JSON, the time
//! per iteration by stage, the Gaussian count, peak memory and bytes per Gaussian. The run is
//! prepared exactly as `train` prepares it (`damage::bench`).

use std::path::PathBuf;
use std::sync::Arc;

use damage_twin::damage::bench::bench_job;
use damage_twin::damage::setup::RunConfig;
use damage_twin::train::job::JobOptions;

use super::args::{RunArgs, drive, open_dataset};

#[derive(clap::Args, Debug)]
pub struct Args {
    pub dataset: PathBuf,
    #[arg(long, default_value_t = 500)]
    pub iters: u32,
    #[command(flatten)]
    pub run: RunArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let dataset = Arc::new(open_dataset(&args.dataset, args.run.background)?);
    let config = RunConfig {
        scale: args.run.scale,
        iterations: args.iters,
        holdout: args.run.holdout.holdout(),
        sh_degree: args.run.sh_degree,
        seed: args.run.seed,
        background: args.run.background,
        random_points: args.run.init_points,
        backend: args.run.backend,
        ..RunConfig::default()
    };
    let job = bench_job(dataset, config, JobOptions::headless(args.run.threads));
    let report = drive(job, "benchmark", true, |_| {})?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
