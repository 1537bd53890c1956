//! `twin update` on a partitioned twin: the blocks `twin detect` found changed (or `--blocks`)
//! retrained on the survey's photos through an engine, merged with the unchanged blocks of the
//! previous model and recorded (`timeline::blocks::update`). Local processes train and record
//! in one go; `slurm` and `k8s` write the engine's job files into the survey's plan folder, whose
//! last job runs this command again to merge and record once every block has trained.

use std::path::PathBuf;

use anyhow::Context;

use damage_twin::timeline::Twin;
use damage_twin::timeline::blocks::changed::MIN_CHANGED_PIXELS;
use damage_twin::timeline::blocks::update::{
    commit_block_update, detected_changed_blocks, merge_block_update, partitioned_previous,
    prepare_block_update, unfinished,
};

use crate::cli::cluster::{Common, K8sResourceArgs, SlurmResourceArgs, k8s, slurm, train_locally};

/// Which blocks a partitioned twin's update retrains.
#[derive(clap::Args, Debug)]
pub struct BlockArgs {
    /// Partitioned twin: retrain these blocks (comma-separated indices) instead of those
    /// `twin detect` found changed.
    #[arg(long, value_delimiter = ',')]
    pub blocks: Option<Vec<usize>>,
    /// Partitioned twin: changed pixels (at the detection's scale) a block needs to be retrained.
    #[arg(long, default_value_t = MIN_CHANGED_PIXELS)]
    pub min_block_pixels: u64,
}

/// The engine a partitioned twin's changed blocks train through.
#[derive(clap::Subcommand, Debug)]
pub enum Engine {
    /// As local processes of this binary, then merge and record (the default, one worker).
    Local {
        #[arg(long, default_value_t = 1)]
        workers: usize,
        /// Threads per worker (default: the cores shared out).
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Write an sbatch array for the changed blocks and a last job that merges and records.
    Slurm {
        #[command(flatten)]
        resources: SlurmResourceArgs,
        #[command(flatten)]
        jobs: EngineJobArgs,
    },
    /// Write a Kubernetes Indexed Job for the changed blocks and a last Job that merges and
    /// records.
    K8s {
        #[command(flatten)]
        resources: K8sResourceArgs,
        #[command(flatten)]
        jobs: EngineJobArgs,
    },
}

/// What every engine job runs.
#[derive(clap::Args, Debug)]
pub struct EngineJobArgs {
    /// The damage-twin binary every node runs (default: this one; same path on every node).
    #[arg(long)]
    pub binary: Option<PathBuf>,
    /// Threads per block job (default: the job's CPUs).
    #[arg(long)]
    pub threads: Option<usize>,
}

pub fn run(mut twin: Twin, args: &super::update::Args) -> anyhow::Result<()> {
    let name = args.survey.as_str();
    let Some((previous, _)) = partitioned_previous(&twin, name)? else {
        anyhow::bail!("the model before survey `{name}` was not merged from blocks");
    };
    let changed = match &args.blocks.blocks {
        Some(blocks) => blocks.clone(),
        None => detected_changed_blocks(&twin, name, &previous, args.blocks.min_block_pixels)?,
    };
    let update = prepare_block_update(&twin, name, &changed)?;
    println!(
        "survey {name} against {previous}: blocks {:?} to train on its photos, {:?} kept; plan {}",
        update.trained,
        update.kept,
        update.plan_dir.display()
    );
    let engine = args.engine.as_ref().unwrap_or(&Engine::Local {
        workers: 1,
        threads: None,
    });
    let waiting = unfinished(&update);
    if !waiting.is_empty() {
        // The engines' last job runs this update again, for the same blocks, to merge and record.
        let finish = |binary: &Option<PathBuf>| -> anyhow::Result<Vec<String>> {
            let binary = match binary {
                Some(b) => b.clone(),
                None => std::env::current_exe().context("finding this binary's path")?,
            };
            let dir = std::fs::canonicalize(&args.dir)
                .with_context(|| format!("opening {}", args.dir.display()))?;
            let blocks: Vec<String> = update.trained.iter().map(|k| k.to_string()).collect();
            let mut line = vec![
                binary.display().to_string(),
                "twin".into(),
                "update".into(),
                dir.display().to_string(),
                "--survey".into(),
                name.to_string(),
            ];
            if !blocks.is_empty() {
                line.push(format!("--blocks={}", blocks.join(",")));
            }
            Ok(line)
        };
        let common = |jobs: &EngineJobArgs| Common {
            plan: update.plan_dir.clone(),
            model: None,
            binary: jobs.binary.clone(),
            threads: jobs.threads,
        };
        match engine {
            Engine::Local { workers, threads } => {
                train_locally(&update.plan_dir, &update.plan, *workers, *threads)?;
            }
            Engine::Slurm { resources, jobs } => {
                let submit = slurm(
                    &common(jobs),
                    resources.clone(),
                    Some(finish(&jobs.binary)?),
                )?;
                println!(
                    "blocks {waiting:?} to train: run {}; its last job merges them and records survey {name}",
                    submit.display()
                );
                return Ok(());
            }
            Engine::K8s { resources, jobs } => {
                let apply = k8s(
                    &common(jobs),
                    resources.clone(),
                    Some(finish(&jobs.binary)?),
                )?;
                println!(
                    "blocks {waiting:?} to train: run {}; its last job merges them and records survey {name}",
                    apply.display()
                );
                return Ok(());
            }
        }
    }
    let (model, report) = merge_block_update(&twin, &update)?;
    let path = commit_block_update(&mut twin, &update, &model, &report)
        .with_context(|| format!("writing {}", twin.file().display()))?;
    println!(
        "updated {name} from {previous}: blocks {:?} trained, {:?} kept as they were; {} Gaussians ({} new-damage); model {}",
        report.trained,
        report.kept,
        report.gaussians,
        report.new_damage_gaussians,
        path.display()
    );
    Ok(())
}
