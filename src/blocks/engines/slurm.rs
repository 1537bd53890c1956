//! Slurm: an `sbatch` array script with one task per block (`train-block` reads
//! `SLURM_ARRAY_TASK_ID`), a merge script, and `submit.sh`, which submits the array and the
//! merge with `--dependency=afterok` on it; with a context, a context script that `submit.sh`
//! submits first, the array depending on it (`afterok`). The plan folder, the dataset and the binary must be
//! at the same path on every node (a shared file system).

use std::path::{Path, PathBuf};

use crate::blocks::engines::{JobCommand, shell_line};
use crate::scene::SceneError;
use crate::scene::atomic::write_atomic;

/// What each job asks of Slurm.
#[derive(Clone, Debug)]
pub struct SlurmResources {
    pub job_name: String,
    pub cpus: usize,
    /// Memory per job in GiB.
    pub mem_gb: usize,
    /// Wall-time limit as Slurm spells it (`HH:MM:SS`, `D-HH:MM:SS`).
    pub time: String,
    pub partition: Option<String>,
}

/// The three files' text.
#[derive(Clone, Debug)]
pub struct SlurmScripts {
    /// The context job (None: the plan has no context).
    pub context: Option<String>,
    pub blocks: String,
    pub merge: String,
    pub submit: String,
}

/// Where `write_slurm` put them.
#[derive(Clone, Debug)]
pub struct SlurmPaths {
    pub context: Option<PathBuf>,
    pub blocks: PathBuf,
    pub merge: PathBuf,
    pub submit: PathBuf,
}

fn header(res: &SlurmResources, name: &str, log: &Path) -> String {
    let mut text = String::from("#!/bin/bash\n");
    text.push_str(&format!("#SBATCH --job-name={name}\n"));
    text.push_str(&format!("#SBATCH --cpus-per-task={}\n", res.cpus.max(1)));
    text.push_str(&format!("#SBATCH --mem={}G\n", res.mem_gb.max(1)));
    text.push_str(&format!("#SBATCH --time={}\n", res.time));
    if let Some(p) = &res.partition {
        text.push_str(&format!("#SBATCH --partition={p}\n"));
    }
    text.push_str(&format!("#SBATCH --output={}\n", log.display()));
    text
}

/// The scripts for a plan of `blocks` blocks whose merge writes `merged_out`; logs go to
/// `logs` (a folder on the shared file system).
pub fn slurm_scripts(
    command: &JobCommand,
    blocks: usize,
    res: &SlurmResources,
    merged_out: &Path,
    logs: &Path,
) -> SlurmScripts {
    let mut block = header(
        res,
        &format!("{}-blocks", res.job_name),
        &logs.join("block-%a.out"),
    );
    block.push_str(&format!("#SBATCH --array=0-{}\n", blocks.saturating_sub(1)));
    block.push_str("set -euo pipefail\n");
    block.push_str("# The block index comes from SLURM_ARRAY_TASK_ID.\n");
    block.push_str(&format!("exec {}\n", shell_line(&command.train_block())));
    let mut merge = header(
        res,
        &format!("{}-merge", res.job_name),
        &logs.join("merge.out"),
    );
    merge.push_str("set -euo pipefail\n");
    merge.push_str(&format!(
        "exec {}\n",
        shell_line(&command.merge(merged_out))
    ));
    let context = command.context.then(|| {
        let mut context = header(
            res,
            &format!("{}-context", res.job_name),
            &logs.join("context.out"),
        );
        context.push_str("set -euo pipefail\n");
        context.push_str(&format!("exec {}\n", shell_line(&command.train_context())));
        context
    });
    let mut submit = String::from(
        "#!/bin/bash\n\
         # Submits the block array (after the context, when the plan has one), then the merge to\n\
         # start when every block succeeded.\n\
         set -euo pipefail\n\
         here=\"$(cd \"$(dirname \"$0\")\" && pwd)\"\n",
    );
    if context.is_some() {
        submit.push_str(
            "context=\"$(sbatch --parsable \"$here/context.sbatch\")\"\n\
             context=\"${context%%;*}\"\n\
             blocks=\"$(sbatch --parsable --dependency=afterok:\"$context\" \"$here/blocks.sbatch\")\"\n",
        );
    } else {
        submit.push_str("blocks=\"$(sbatch --parsable \"$here/blocks.sbatch\")\"\n");
    }
    submit.push_str(
        "blocks=\"${blocks%%;*}\"\n\
         merge=\"$(sbatch --parsable --dependency=afterok:\"$blocks\" \"$here/merge.sbatch\")\"\n\
         echo \"blocks job $blocks, merge job ${merge%%;*}\"\n",
    );
    SlurmScripts {
        context,
        blocks: block,
        merge,
        submit,
    }
}

/// Writes `scripts` into `dir` (created; scripts executable) and the `logs` folder they log to.
pub fn write_slurm(
    dir: &Path,
    scripts: &SlurmScripts,
    logs: &Path,
) -> Result<SlurmPaths, SceneError> {
    std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;
    std::fs::create_dir_all(logs).map_err(|e| SceneError::io(logs, e))?;
    let paths = SlurmPaths {
        context: scripts.context.as_ref().map(|_| dir.join("context.sbatch")),
        blocks: dir.join("blocks.sbatch"),
        merge: dir.join("merge.sbatch"),
        submit: dir.join("submit.sh"),
    };
    for (path, text) in [
        (&paths.blocks, &scripts.blocks),
        (&paths.merge, &scripts.merge),
        (&paths.submit, &scripts.submit),
    ] {
        write_atomic(path, |w| std::io::Write::write_all(w, text.as_bytes()))?;
        make_executable(path)?;
    }
    if let (Some(path), Some(text)) = (&paths.context, &scripts.context) {
        write_atomic(path, |w| std::io::Write::write_all(w, text.as_bytes()))?;
        make_executable(path)?;
    }
    Ok(paths)
}

#[cfg(unix)]
fn make_executable(path: &Path) -> Result<(), SceneError> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755))
        .map_err(|e| SceneError::io(path, e))
}

#[cfg(not(unix))]
fn make_executable(_: &Path) -> Result<(), SceneError> {
    Ok(())
}
