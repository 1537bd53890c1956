//! Kubernetes: an Indexed Job (`completionMode: Indexed`, one completion per block; each pod
//! gets `JOB_COMPLETION_INDEX`, which `train-block` reads) and a one-pod merge Job, both
//! mounting one shared volume (a PersistentVolumeClaim, ReadWriteMany) at the same path, under
//! which the plan folder and the dataset lie; with a context, a one-pod context Job before the
//! blocks. Written as JSON, which `kubectl apply -f` reads like YAML; `apply.sh` applies the
//! context and waits for it to complete (`kubectl wait --for=condition=complete`), then the
//! blocks, waits for them, then applies the merge.

use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use crate::blocks::engines::{JobCommand, shell_line};
use crate::scene::SceneError;
use crate::scene::atomic::write_atomic;

/// What the Jobs run on and ask for.
#[derive(Clone, Debug)]
pub struct K8sSettings {
    /// Job name prefix (a DNS label: lower case, digits, '-').
    pub name: String,
    /// The container image holding the damage-twin binary at `JobCommand::binary`.
    pub image: String,
    /// The PersistentVolumeClaim of the shared volume.
    pub claim: String,
    /// Where the shared volume is mounted in every pod (the plan and the dataset are under it).
    pub mount: PathBuf,
    /// Blocks trained at once.
    pub parallelism: usize,
    pub cpus: usize,
    pub mem_gb: usize,
}

fn pod_spec(settings: &K8sSettings, container: &str, command: Vec<String>) -> Value {
    let quantity = json!({
        "cpu": settings.cpus.max(1).to_string(),
        "memory": format!("{}Gi", settings.mem_gb.max(1)),
    });
    json!({
        "restartPolicy": "Never",
        "containers": [{
            "name": container,
            "image": settings.image,
            "command": command,
            "resources": { "requests": quantity.clone(), "limits": quantity },
            "volumeMounts": [{ "name": "shared", "mountPath": settings.mount.display().to_string() }],
        }],
        "volumes": [{
            "name": "shared",
            "persistentVolumeClaim": { "claimName": settings.claim },
        }],
    })
}

/// The Indexed Job of a plan's `blocks` blocks.
pub fn blocks_job(command: &JobCommand, blocks: usize, settings: &K8sSettings) -> Value {
    json!({
        "apiVersion": "batch/v1",
        "kind": "Job",
        "metadata": {
            "name": format!("{}-blocks", settings.name),
            "labels": { "app.kubernetes.io/name": "damage-twin", "damage-twin/part": "blocks" },
        },
        "spec": {
            "completionMode": "Indexed",
            "completions": blocks,
            "parallelism": settings.parallelism.clamp(1, blocks.max(1)),
            // A killed block restarts cleanly (its run folder), so retrying is safe.
            "backoffLimit": 2 * blocks.max(1),
            "template": {
                "metadata": { "labels": { "app.kubernetes.io/name": "damage-twin" } },
                "spec": pod_spec(settings, "block", command.train_block()),
            },
        },
    })
}

/// The merge Job, writing the merged model to `merged_out`.
pub fn merge_job(command: &JobCommand, settings: &K8sSettings, merged_out: &Path) -> Value {
    one_pod_job(settings, "merge", command.merge(merged_out))
}

/// The context Job (`train-block PLAN --context`), run before the blocks.
pub fn context_job(command: &JobCommand, settings: &K8sSettings) -> Value {
    one_pod_job(settings, "context", command.train_context())
}

/// A Job of one pod named `{name}-{part}` running `run`.
fn one_pod_job(settings: &K8sSettings, part: &str, run: Vec<String>) -> Value {
    json!({
        "apiVersion": "batch/v1",
        "kind": "Job",
        "metadata": {
            "name": format!("{}-{part}", settings.name),
            "labels": { "app.kubernetes.io/name": "damage-twin", "damage-twin/part": part },
        },
        "spec": {
            "completions": 1,
            "parallelism": 1,
            "backoffLimit": 2,
            "template": {
                "metadata": { "labels": { "app.kubernetes.io/name": "damage-twin" } },
                "spec": pod_spec(settings, part, run),
            },
        },
    })
}

/// Where `write_k8s` put the files.
#[derive(Clone, Debug)]
pub struct K8sPaths {
    /// The context Job (None: the plan has no context).
    pub context: Option<PathBuf>,
    pub blocks: PathBuf,
    pub merge: PathBuf,
    pub apply: PathBuf,
}

/// Writes both Jobs and `apply.sh` into `dir`.
pub fn write_k8s(
    dir: &Path,
    command: &JobCommand,
    blocks: usize,
    settings: &K8sSettings,
    merged_out: &Path,
) -> Result<K8sPaths, SceneError> {
    std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;
    let paths = K8sPaths {
        context: command.context.then(|| dir.join("context-job.json")),
        blocks: dir.join("blocks-job.json"),
        merge: dir.join("merge-job.json"),
        apply: dir.join("apply.sh"),
    };
    let pretty = |v: &Value| serde_json::to_string_pretty(v).unwrap_or_default() + "\n";
    let wait = |part: &str| {
        format!(
            "kubectl wait --for=condition=complete --timeout=-1s job/{}\n",
            shell_line(&[format!("{}-{part}", settings.name)])
        )
    };
    let mut apply = String::from(
        "#!/bin/bash\n\
         # Applies the context Job (when the plan has one) and waits for it, then the block Job,\n\
         # waits for every block, then applies the merge Job.\n\
         set -euo pipefail\n\
         here=\"$(cd \"$(dirname \"$0\")\" && pwd)\"\n",
    );
    if let Some(path) = &paths.context {
        let text = pretty(&context_job(command, settings));
        write_atomic(path, |w| std::io::Write::write_all(w, text.as_bytes()))?;
        apply.push_str("kubectl apply -f \"$here/context-job.json\"\n");
        apply.push_str(&wait("context"));
    }
    apply.push_str("kubectl apply -f \"$here/blocks-job.json\"\n");
    apply.push_str(&wait("blocks"));
    apply.push_str("kubectl apply -f \"$here/merge-job.json\"\n");
    for (path, text) in [
        (
            &paths.blocks,
            pretty(&blocks_job(command, blocks, settings)),
        ),
        (
            &paths.merge,
            pretty(&merge_job(command, settings, merged_out)),
        ),
        (&paths.apply, apply),
    ] {
        write_atomic(path, |w| std::io::Write::write_all(w, text.as_bytes()))?;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&paths.apply, std::fs::Permissions::from_mode(0o755))
            .map_err(|e| SceneError::io(&paths.apply, e))?;
    }
    Ok(paths)
}
