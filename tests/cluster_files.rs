//! The engines' job files (docs/CLUSTER.md). The Kubernetes manifests are checked against the
//! `batch/v1` Job schema without a cluster: every field the generator writes is read into a typed
//! model of the Job, written here from the Kubernetes API reference (batch/v1 Job, JobSpec,
//! PodTemplateSpec, PodSpec, Container, ResourceRequirements, VolumeMount, Volume,
//! PersistentVolumeClaimVolumeSource), with `deny_unknown_fields` on every object (a misspelt
//! or misplaced field fails) and the schema's required fields non-optional; then the values the
//! API server checks (completionMode, restartPolicy of a Job's pods, DNS names, quantities,
//! mounts of declared volumes) are checked too. The Slurm script is parsed: shebang, the array
//! over every block, resources, and the command.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use damage_twin::blocks::engines::JobCommand;
use damage_twin::blocks::engines::k8s::{K8sSettings, blocks_job, merge_job, write_k8s};
use damage_twin::blocks::engines::slurm::{SlurmResources, slurm_scripts, write_slurm};

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
struct Job {
    api_version: String,
    kind: String,
    metadata: ObjectMeta,
    spec: JobSpec,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
struct ObjectMeta {
    name: Option<String>,
    #[serde(default)]
    labels: BTreeMap<String, String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
struct JobSpec {
    completions: Option<i32>,
    parallelism: Option<i32>,
    completion_mode: Option<String>,
    backoff_limit: Option<i32>,
    template: PodTemplateSpec,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
struct PodTemplateSpec {
    metadata: Option<ObjectMeta>,
    spec: PodSpec,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
struct PodSpec {
    restart_policy: Option<String>,
    containers: Vec<Container>,
    #[serde(default)]
    volumes: Vec<Volume>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
struct Container {
    name: String,
    image: Option<String>,
    #[serde(default)]
    command: Vec<String>,
    resources: Option<ResourceRequirements>,
    #[serde(default)]
    volume_mounts: Vec<VolumeMount>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ResourceRequirements {
    #[serde(default)]
    requests: BTreeMap<String, String>,
    #[serde(default)]
    limits: BTreeMap<String, String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
struct VolumeMount {
    name: String,
    mount_path: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
struct Volume {
    name: String,
    persistent_volume_claim: Option<ClaimSource>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
struct ClaimSource {
    claim_name: String,
}

fn dns_label(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 63
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
        && !name.starts_with('-')
        && !name.ends_with('-')
}

/// The Job checks the API server makes on what we write; returns the Job.
fn valid_job(text: &str) -> Job {
    let job: Job = serde_json::from_str(text).unwrap_or_else(|e| panic!("not a batch/v1 Job: {e}"));
    assert_eq!(job.api_version, "batch/v1");
    assert_eq!(job.kind, "Job");
    assert!(dns_label(job.metadata.name.as_deref().unwrap()));
    for (k, v) in &job.metadata.labels {
        assert!(k.len() <= 317 && v.len() <= 63, "label {k}={v}");
    }
    let spec = &job.spec;
    assert!(spec.completions.unwrap() >= 1);
    assert!(spec.parallelism.unwrap() >= 1);
    assert!(spec.backoff_limit.unwrap() >= 0);
    if let Some(mode) = &spec.completion_mode {
        assert!(mode == "Indexed" || mode == "NonIndexed", "{mode}");
    }
    let _ = &spec.template.metadata;
    let pod = &spec.template.spec;
    // A Job's pods may only restart Never or OnFailure.
    assert!(matches!(
        pod.restart_policy.as_deref(),
        Some("Never" | "OnFailure")
    ));
    assert!(!pod.containers.is_empty());
    let volumes: Vec<&str> = pod.volumes.iter().map(|v| v.name.as_str()).collect();
    for volume in &pod.volumes {
        assert!(dns_label(&volume.name));
        assert!(
            !volume
                .persistent_volume_claim
                .as_ref()
                .unwrap()
                .claim_name
                .is_empty()
        );
    }
    for container in &pod.containers {
        assert!(dns_label(&container.name));
        assert!(!container.image.as_deref().unwrap().is_empty());
        assert!(!container.command.is_empty());
        let resources = container.resources.as_ref().unwrap();
        for quantities in [&resources.requests, &resources.limits] {
            for (name, q) in quantities {
                assert!(name == "cpu" || name == "memory", "{name}");
                assert!(
                    q.trim_end_matches("Gi").chars().all(|c| c.is_ascii_digit()),
                    "quantity {q}"
                );
            }
        }
        for mount in &container.volume_mounts {
            assert!(
                volumes.contains(&mount.name.as_str()),
                "mount of an undeclared volume"
            );
            assert!(Path::new(&mount.mount_path).is_absolute());
        }
    }
    job
}

fn command() -> JobCommand {
    JobCommand {
        binary: PathBuf::from("/shared/bin/damage-twin"),
        plan_dir: PathBuf::from("/shared/bridge/plan"),
        threads: Some(8),
        finish: None,
        context: false,
    }
}

fn settings() -> K8sSettings {
    K8sSettings {
        name: "bridge".into(),
        image: "registry.example/damage-twin:1".into(),
        claim: "survey-data".into(),
        mount: PathBuf::from("/shared"),
        parallelism: 3,
        cpus: 8,
        mem_gb: 24,
    }
}

#[test]
fn the_kubernetes_jobs_are_batch_v1_jobs_indexed_over_the_blocks() {
    let blocks = blocks_job(&command(), 7, &settings()).to_string();
    let job = valid_job(&blocks);
    assert_eq!(job.spec.completion_mode.as_deref(), Some("Indexed"));
    assert_eq!(job.spec.completions, Some(7));
    assert_eq!(job.spec.parallelism, Some(3));
    let container = &job.spec.template.spec.containers[0];
    assert_eq!(
        container.command[..3],
        [
            "/shared/bin/damage-twin",
            "train-block",
            "/shared/bridge/plan"
        ]
    );
    assert!(
        !container.command.iter().any(|a| a == "--block"),
        "the index comes from the pod"
    );
    assert_eq!(container.volume_mounts[0].mount_path, "/shared");
    assert_eq!(
        container.resources.as_ref().unwrap().limits["memory"],
        "24Gi"
    );

    let merge = merge_job(&command(), &settings(), Path::new("/shared/bridge/merged")).to_string();
    let job = valid_job(&merge);
    assert_eq!(job.spec.completions, Some(1));
    assert_eq!(job.spec.template.spec.containers[0].command[1], "merge");

    // Parallelism never exceeds the blocks; the files on disk are the same Jobs.
    let one = valid_job(&blocks_job(&command(), 1, &settings()).to_string());
    assert_eq!(one.spec.parallelism, Some(1));
    let dir = tempfile::tempdir().unwrap();
    let paths = write_k8s(
        dir.path(),
        &command(),
        7,
        &settings(),
        Path::new("/shared/m"),
    )
    .unwrap();
    valid_job(&std::fs::read_to_string(&paths.blocks).unwrap());
    valid_job(&std::fs::read_to_string(&paths.merge).unwrap());
    let apply = std::fs::read_to_string(&paths.apply).unwrap();
    assert!(
        apply.contains("kubectl wait --for=condition=complete")
            && apply.contains("job/bridge-blocks")
    );
}

#[test]
fn a_misplaced_field_fails_the_schema_check() {
    // The check itself can fail: a field at the wrong level, or a misspelt one, is refused.
    let mut job = blocks_job(&command(), 3, &settings());
    job["spec"]["completionsMode"] = "Indexed".into();
    assert!(serde_json::from_value::<Job>(job).is_err());
    let mut job = blocks_job(&command(), 3, &settings());
    job["spec"]["template"]["spec"]["containers"][0]["mountPath"] = "/x".into();
    assert!(serde_json::from_value::<Job>(job).is_err());
    let mut job = blocks_job(&command(), 3, &settings());
    job["spec"].as_object_mut().unwrap().remove("template");
    assert!(serde_json::from_value::<Job>(job).is_err());
}

#[test]
fn the_slurm_array_covers_every_block_and_the_merge_waits_for_it() {
    let resources = SlurmResources {
        job_name: "bridge".into(),
        cpus: 16,
        mem_gb: 32,
        time: "02:00:00".into(),
        partition: Some("gpu".into()),
    };
    let logs = Path::new("/shared/bridge/plan/logs");
    let scripts = slurm_scripts(&command(), 12, &resources, Path::new("/shared/m"), logs);
    let lines: Vec<&str> = scripts.blocks.lines().collect();
    assert_eq!(lines[0], "#!/bin/bash");
    let directives: BTreeMap<&str, &str> = lines
        .iter()
        .filter_map(|l| l.strip_prefix("#SBATCH --"))
        .map(|d| d.split_once('=').unwrap())
        .collect();
    assert_eq!(directives["array"], "0-11");
    assert_eq!(directives["cpus-per-task"], "16");
    assert_eq!(directives["mem"], "32G");
    assert_eq!(directives["time"], "02:00:00");
    assert_eq!(directives["partition"], "gpu");
    assert_eq!(
        directives["output"],
        "/shared/bridge/plan/logs/block-%a.out"
    );
    // Every directive comes before the first command (sbatch stops reading at it).
    let first_command = lines.iter().position(|l| !l.starts_with('#')).unwrap();
    assert!(
        lines[first_command..]
            .iter()
            .all(|l| !l.starts_with("#SBATCH"))
    );
    let exec = lines.iter().find(|l| l.starts_with("exec ")).unwrap();
    assert_eq!(
        *exec,
        "exec /shared/bin/damage-twin train-block /shared/bridge/plan --quiet --threads 8"
    );
    assert!(
        scripts
            .merge
            .contains("exec /shared/bin/damage-twin merge /shared/bridge/plan --out /shared/m")
    );
    assert!(!scripts.merge.contains("--array"));
    assert!(scripts.submit.contains("--dependency=afterok:"));

    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join("logs");
    let paths = write_slurm(&dir.path().join("slurm"), &scripts, &logs).unwrap();
    assert_eq!(
        std::fs::read_to_string(&paths.blocks).unwrap(),
        scripts.blocks
    );
    assert!(logs.is_dir());
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&paths.submit)
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o111, 0o111);
    }
}

#[test]
fn a_plan_with_a_context_runs_its_context_job_before_the_blocks() {
    let with_context = JobCommand {
        context: true,
        ..command()
    };
    // Kubernetes: a one-pod context Job, a valid batch/v1 Job running `train-block --context`,
    // applied and waited for before the blocks.
    let dir = tempfile::tempdir().unwrap();
    let paths = write_k8s(
        dir.path(),
        &with_context,
        3,
        &settings(),
        Path::new("/shared/m"),
    )
    .unwrap();
    let job = valid_job(&std::fs::read_to_string(paths.context.as_ref().unwrap()).unwrap());
    assert_eq!(job.spec.completions, Some(1));
    assert_eq!(job.spec.completion_mode, None);
    assert_eq!(
        job.spec.template.spec.containers[0].command,
        [
            "/shared/bin/damage-twin",
            "train-block",
            "/shared/bridge/plan",
            "--context",
            "--quiet",
            "--threads",
            "8"
        ]
    );
    let apply = std::fs::read_to_string(&paths.apply).unwrap();
    let at = |what: &str| {
        apply
            .find(what)
            .unwrap_or_else(|| panic!("{what} not in {apply}"))
    };
    assert!(at("context-job.json") < at("job/bridge-context"));
    assert!(at("job/bridge-context") < at("blocks-job.json"));
    assert!(at("blocks-job.json") < at("job/bridge-blocks"));
    assert!(at("job/bridge-blocks") < at("merge-job.json"));
    // Without a context there is no context Job.
    let plain = tempfile::tempdir().unwrap();
    let paths = write_k8s(plain.path(), &command(), 3, &settings(), Path::new("/m")).unwrap();
    assert!(paths.context.is_none() && !plain.path().join("context-job.json").exists());
    let apply = std::fs::read_to_string(&paths.apply).unwrap();
    assert!(!apply.contains("context-job.json") && !apply.contains("job/bridge-context"));

    // Slurm: a context script, submitted first; the array depends on it, the merge on the array.
    let resources = SlurmResources {
        job_name: "bridge".into(),
        cpus: 4,
        mem_gb: 8,
        time: "01:00:00".into(),
        partition: None,
    };
    let logs = Path::new("/shared/bridge/plan/logs");
    let scripts = slurm_scripts(&with_context, 3, &resources, Path::new("/shared/m"), logs);
    let context = scripts.context.as_ref().expect("a context script");
    assert!(context.contains("#SBATCH --output=/shared/bridge/plan/logs/context.out"));
    assert!(!context.contains("--array"));
    assert!(context.contains(
        "exec /shared/bin/damage-twin train-block /shared/bridge/plan --context --quiet --threads 8"
    ));
    let submit = &scripts.submit;
    assert!(
        submit.contains("sbatch --parsable \"$here/context.sbatch\"")
            && submit.contains(
                "sbatch --parsable --dependency=afterok:\"$context\" \"$here/blocks.sbatch\""
            )
            && submit.contains(
                "sbatch --parsable --dependency=afterok:\"$blocks\" \"$here/merge.sbatch\""
            ),
        "{submit}"
    );
    let dir = tempfile::tempdir().unwrap();
    let written = write_slurm(
        &dir.path().join("slurm"),
        &scripts,
        &dir.path().join("logs"),
    )
    .unwrap();
    assert_eq!(
        std::fs::read_to_string(written.context.unwrap()).unwrap(),
        *context
    );
    let plain = slurm_scripts(&command(), 3, &resources, Path::new("/shared/m"), logs);
    assert!(plain.context.is_none() && !plain.submit.contains("context.sbatch"));
    assert!(
        plain
            .submit
            .contains("blocks=\"$(sbatch --parsable \"$here/blocks.sbatch\")\"")
    );
}
