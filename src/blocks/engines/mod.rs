//! The engines that run a plan's blocks: job files for Slurm (an `sbatch` array and a merge job
//! after it) and Kubernetes (an Indexed Job and a merge Job), and the block index a job reads
//! from its engine's environment. Local processes are started by the CLI (`cluster local`).
//! The engines schedule; damage-twin only writes what they run.

pub mod index;
pub mod k8s;
pub mod slurm;

/// What every engine's job runs: the binary at the same path on every node, and the plan
/// folder (the shared directory) at the same path on every node.
#[derive(Clone, Debug)]
pub struct JobCommand {
    pub binary: std::path::PathBuf,
    pub plan_dir: std::path::PathBuf,
    /// Threads per block job (`--threads`; None: the job's CPUs).
    pub threads: Option<usize>,
    /// What the last job runs instead of `merge PLAN --out MODEL` (None: the merge); `twin
    /// update` on a partitioned twin merges and records into the twin this way.
    pub finish: Option<Vec<String>>,
    /// Whether the plan has a context (`Plan::context`): its job runs first, the blocks after it.
    pub context: bool,
}

impl JobCommand {
    /// The block job's command line (the block index comes from the engine's environment).
    pub fn train_block(&self) -> Vec<String> {
        let mut args = vec![
            self.binary.display().to_string(),
            "train-block".into(),
            self.plan_dir.display().to_string(),
            "--quiet".into(),
        ];
        if let Some(t) = self.threads {
            args.extend(["--threads".into(), t.to_string()]);
        }
        args
    }

    /// The context job's command line (`train-block PLAN --context`).
    pub fn train_context(&self) -> Vec<String> {
        let mut args = self.train_block();
        args.insert(3, "--context".into());
        args
    }

    /// The merge job's command line, writing the merged model to `out` (or `finish`).
    pub fn merge(&self, out: &std::path::Path) -> Vec<String> {
        if let Some(finish) = &self.finish {
            return finish.clone();
        }
        vec![
            self.binary.display().to_string(),
            "merge".into(),
            self.plan_dir.display().to_string(),
            "--out".into(),
            out.display().to_string(),
        ]
    }
}

/// `args` as one shell command line, each word quoted when it needs it.
pub fn shell_line(args: &[String]) -> String {
    args.iter()
        .map(|a| {
            if !a.is_empty()
                && a.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "/._-=:,+@%".contains(c))
            {
                a.clone()
            } else {
                format!("'{}'", a.replace('\'', r"'\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}
