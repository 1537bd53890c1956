//! `damage-twin cluster slurm|k8s|local PLAN`: runs a plan's blocks through an engine. `slurm`
//! and `k8s` write the engine's job files into the plan folder (`blocks::engines`); `local`
//! runs the blocks as child processes of this binary, N at a time, then merges when asked.
//! docs/CLUSTER.md says what each engine needs.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};

use anyhow::Context;

use damage_twin::blocks::block_run::finished;
use damage_twin::blocks::context_run::context_finished;
use damage_twin::blocks::engines::JobCommand;
use damage_twin::blocks::engines::k8s::{K8sSettings, write_k8s};
use damage_twin::blocks::engines::slurm::{SlurmResources, slurm_scripts, write_slurm};
use damage_twin::blocks::{Plan, load_plan, plan_folder};

#[derive(clap::Subcommand, Debug)]
pub enum Cluster {
    /// Write an sbatch array script (one task per block), a merge script that runs after it
    /// (--dependency=afterok) and submit.sh into PLAN/slurm/.
    Slurm(SlurmArgs),
    /// Write a Kubernetes Indexed Job (one completion per block), a merge Job and apply.sh into
    /// PLAN/k8s/.
    K8s(K8sArgs),
    /// Run the blocks as N local processes of this binary, then merge with --out.
    Local(LocalArgs),
}

#[derive(clap::Args, Debug)]
pub struct Common {
    /// The plan folder (the shared directory).
    pub plan: PathBuf,
    /// Where the merge job writes the merged model (default: PLAN/merged).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// The damage-twin binary every node runs (default: this one; same path on every node).
    #[arg(long)]
    pub binary: Option<PathBuf>,
    /// Threads per block job (default: the job's CPUs).
    #[arg(long)]
    pub threads: Option<usize>,
}

#[derive(clap::Args, Debug)]
pub struct SlurmArgs {
    #[command(flatten)]
    pub common: Common,
    #[command(flatten)]
    pub resources: SlurmResourceArgs,
}

/// What each Slurm job asks for.
#[derive(clap::Args, Clone, Debug)]
pub struct SlurmResourceArgs {
    #[arg(long, default_value_t = 8)]
    pub cpus: usize,
    /// Memory per job in GiB.
    #[arg(long, default_value_t = 16)]
    pub mem: usize,
    /// Wall-time limit per job (Slurm's HH:MM:SS or D-HH:MM:SS).
    #[arg(long, default_value = "04:00:00")]
    pub time: String,
    #[arg(long)]
    pub partition: Option<String>,
    #[arg(long, default_value = "damage-twin")]
    pub job_name: String,
}

#[derive(clap::Args, Debug)]
pub struct K8sArgs {
    #[command(flatten)]
    pub common: Common,
    #[command(flatten)]
    pub resources: K8sResourceArgs,
}

/// Where each Kubernetes pod runs and what it asks for.
#[derive(clap::Args, Clone, Debug)]
pub struct K8sResourceArgs {
    /// Container image with the binary at --binary.
    #[arg(long, default_value = "damage-twin:latest")]
    pub image: String,
    /// PersistentVolumeClaim of the shared volume (ReadWriteMany).
    #[arg(long, default_value = "damage-twin-shared")]
    pub claim: String,
    /// Mount path of the shared volume in every pod (default: the deepest folder holding both
    /// the plan folder and the dataset).
    #[arg(long)]
    pub mount: Option<PathBuf>,
    #[arg(long, default_value_t = 4)]
    pub parallelism: usize,
    #[arg(long, default_value_t = 8)]
    pub cpus: usize,
    #[arg(long, default_value_t = 16)]
    pub mem: usize,
    #[arg(long, default_value = "damage-twin")]
    pub name: String,
}

#[derive(clap::Args, Debug)]
pub struct LocalArgs {
    /// The plan folder.
    pub plan: PathBuf,
    /// Blocks trained at once.
    #[arg(long, default_value_t = 1)]
    pub workers: usize,
    /// Threads per worker (default: the cores shared out among the workers).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Merge into this folder once every block is trained.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn run(command: Cluster) -> anyhow::Result<()> {
    match command {
        Cluster::Slurm(args) => slurm(&args.common, args.resources, None).map(drop),
        Cluster::K8s(args) => k8s(&args.common, args.resources, None).map(drop),
        Cluster::Local(args) => local(args),
    }
}

/// The plan, its folder (absolute) and the command every job runs (the last job `finish`, in
/// place of the merge, when given).
fn job_command(
    common: &Common,
    finish: Option<Vec<String>>,
) -> anyhow::Result<(Plan, PathBuf, JobCommand, PathBuf)> {
    let plan = load_plan(&common.plan)?;
    let dir = std::fs::canonicalize(plan_folder(&common.plan))
        .with_context(|| format!("opening plan folder {}", common.plan.display()))?;
    let binary = match &common.binary {
        Some(b) => b.clone(),
        None => std::env::current_exe().context("finding this binary's path")?,
    };
    let model = common.model.clone().unwrap_or_else(|| dir.join("merged"));
    let command = JobCommand {
        binary,
        plan_dir: dir.clone(),
        threads: common.threads,
        finish,
        context: plan.context.is_some(),
    };
    Ok((plan, dir, command, model))
}

/// Writes the Slurm job files of the plan `common` names; `finish` replaces the merge job's
/// command (`twin update` records into the twin instead).
pub(crate) fn slurm(
    common: &Common,
    args: SlurmResourceArgs,
    finish: Option<Vec<String>>,
) -> anyhow::Result<PathBuf> {
    let (plan, dir, command, model) = job_command(common, finish)?;
    let resources = SlurmResources {
        job_name: args.job_name,
        cpus: args.cpus,
        mem_gb: args.mem,
        time: args.time,
        partition: args.partition,
    };
    let logs = dir.join("logs");
    let scripts = slurm_scripts(&command, plan.blocks.len(), &resources, &model, &logs);
    let paths = write_slurm(&dir.join("slurm"), &scripts, &logs)?;
    println!(
        "wrote {} ({} array tasks), {} and {}: run {}",
        paths.blocks.display(),
        plan.blocks.len(),
        paths.merge.display(),
        paths.submit.display(),
        paths.submit.display()
    );
    Ok(paths.submit)
}

/// The deepest folder holding both `a` and `b`.
fn common_ancestor(a: &Path, b: &Path) -> PathBuf {
    let mut shared = PathBuf::new();
    for (x, y) in a.components().zip(b.components()) {
        if x != y {
            break;
        }
        shared.push(x);
    }
    shared
}

/// Writes the Kubernetes job files of the plan `common` names; `finish` as for `slurm`.
pub(crate) fn k8s(
    common: &Common,
    args: K8sResourceArgs,
    finish: Option<Vec<String>>,
) -> anyhow::Result<PathBuf> {
    let (plan, dir, command, model) = job_command(common, finish)?;
    let mount = args
        .mount
        .unwrap_or_else(|| common_ancestor(&dir, &plan.dataset));
    if mount.parent().is_none() {
        anyhow::bail!(
            "the shared volume cannot be mounted at the root: give --mount, the folder holding the plan folder {} and the dataset {}",
            dir.display(),
            plan.dataset.display()
        );
    }
    for path in [&dir, &plan.dataset, &model] {
        if !path.starts_with(&mount) {
            anyhow::bail!(
                "{} is not under the shared volume's mount {}: pods would not see it",
                path.display(),
                mount.display()
            );
        }
    }
    let settings = K8sSettings {
        name: args.name,
        image: args.image,
        claim: args.claim,
        mount,
        parallelism: args.parallelism,
        cpus: args.cpus,
        mem_gb: args.mem,
    };
    let paths = write_k8s(
        &dir.join("k8s"),
        &command,
        plan.blocks.len(),
        &settings,
        &model,
    )?;
    println!(
        "wrote {} ({} completions), {} and {}: run {}",
        paths.blocks.display(),
        plan.blocks.len(),
        paths.merge.display(),
        paths.apply.display(),
        paths.apply.display()
    );
    Ok(paths.apply)
}

/// Trains `plan`'s unfinished, unskipped blocks (its folder `dir`) as child processes of this
/// binary, `workers` at a time with `threads` each (default: the cores shared out).
pub(crate) fn train_locally(
    dir: &Path,
    plan: &Plan,
    workers: usize,
    threads: Option<usize>,
) -> anyhow::Result<()> {
    let workers = workers.max(1);
    let threads = threads.unwrap_or_else(|| {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        (cores / workers).max(1)
    });
    let binary = std::env::current_exe().context("finding this binary's path")?;
    // The context first, on every worker's cores: each block renders it.
    if plan.context.is_some() && context_finished(dir, plan).is_none() {
        println!("training the context on {} threads", workers * threads);
        let status = Command::new(&binary)
            .arg("train-block")
            .arg(dir)
            .args(["--context", "--quiet"])
            .args(["--threads", &(workers * threads).to_string()])
            .status()
            .context("starting the context")?;
        if !status.success() {
            anyhow::bail!("the context failed ({status}); rerun to retrain it");
        }
    }
    let mut queue: VecDeque<usize> = (0..plan.blocks.len())
        .filter(|&k| plan.blocks[k].skipped.is_none() && finished(dir, plan, k).is_none())
        .collect();
    println!(
        "{} blocks to train on {workers} local workers ({threads} threads each)",
        queue.len()
    );
    let mut running: Vec<(usize, Child)> = Vec::new();
    let mut failed = Vec::new();
    while !queue.is_empty() || !running.is_empty() {
        while running.len() < workers
            && let Some(k) = queue.pop_front()
        {
            let child = Command::new(&binary)
                .arg("train-block")
                .arg(dir)
                .args(["--block", &k.to_string(), "--quiet"])
                .args(["--threads", &threads.to_string()])
                .spawn()
                .with_context(|| format!("starting block {k}"))?;
            running.push((k, child));
        }
        // Whichever block ends first frees its worker for the next.
        let mut ended = None;
        for (i, (k, child)) in running.iter_mut().enumerate() {
            if let Some(status) = child
                .try_wait()
                .with_context(|| format!("waiting for block {k}"))?
            {
                ended = Some((i, status));
                break;
            }
        }
        match ended {
            Some((i, status)) => {
                let (k, _) = running.remove(i);
                if !status.success() {
                    eprintln!("block {k} failed ({status})");
                    failed.push(k);
                }
            }
            None => std::thread::sleep(std::time::Duration::from_millis(100)),
        }
    }
    if !failed.is_empty() {
        anyhow::bail!(
            "blocks {failed:?} failed; rerun to retrain only them (finished blocks are kept)"
        );
    }
    Ok(())
}

fn local(args: LocalArgs) -> anyhow::Result<()> {
    let plan = load_plan(&args.plan)?;
    let dir = plan_folder(&args.plan);
    train_locally(&dir, &plan, args.workers, args.threads)?;
    if let Some(out) = &args.out {
        println!("{}", super::merge::merge(&args.plan, out, true)?);
    }
    Ok(())
}
