//! Block training on a real Slurm engine (issue 43 §7): a private single-node cluster
//! (tests/slurm_support) runs what `damage-twin cluster slurm` writes for a tiny building's
//! two-block plan — `submit.sh` submits the block array and the merge job that depends on it —
//! and the merged model is, byte for byte, the one `cluster local` makes from the same plan.
//! Skipped with a printed reason where Slurm cannot start (not root, packages missing), unless
//! `DAMAGE_TWIN_REQUIRE_SLURM=1` (set by `.ci/run`).

use std::time::Duration;

mod blocks_support;
mod slurm_support;

use blocks_support::{binary, cluster_local_two_workers, run, tiny_plan};
use slurm_support::SlurmCluster;

#[test]
fn slurm_trains_the_blocks_and_merges_like_the_local_engine() {
    let Some(cluster) = SlurmCluster::start_or_skip("slurm_blocks") else {
        return;
    };
    // The cluster's folder is the shared storage: the plan, the dataset and the logs live there.
    let plan = tiny_plan(cluster.dir(), "plan");
    let merged = cluster.dir().join("merged");
    let mut write = binary();
    write
        .args(["cluster", "slurm"])
        .arg(&plan)
        .args([
            "--cpus",
            "1",
            "--mem",
            "1",
            "--time",
            "00:10:00",
            "--threads",
            "1",
        ])
        .arg("--binary")
        .arg(env!("CARGO_BIN_EXE_damage-twin"))
        .arg("--model")
        .arg(&merged);
    run(write);
    let submit = plan.join("slurm/submit.sh");
    let submitted = cluster.command("bash").arg(&submit).output().unwrap();
    let printed = String::from_utf8_lossy(&submitted.stdout).to_string();
    assert!(
        submitted.status.success(),
        "{}: {printed}{}",
        submit.display(),
        String::from_utf8_lossy(&submitted.stderr)
    );
    // "blocks job N, merge job M"
    let merge_id: u64 = printed
        .trim()
        .rsplit(' ')
        .next()
        .and_then(|id| id.parse().ok())
        .unwrap_or_else(|| panic!("submit.sh printed {printed:?}"));
    let records = cluster
        .wait_for_job(merge_id, Duration::from_secs(300))
        .unwrap_or_else(|e| panic!("{e}{}", cluster.logs()));
    let logs = std::fs::read_dir(plan.join("slurm"))
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path().display().to_string())
        .collect::<Vec<_>>()
        .join(", ");
    assert_eq!(
        records,
        vec![("COMPLETED".to_string(), "0:0".to_string())],
        "merge job (files: {logs}){}",
        cluster.logs()
    );

    // The same plan trained by the local engine gives the same merged model.
    let local_plan = tiny_plan(cluster.dir(), "local");
    let local_merged = cluster.dir().join("merged-local");
    cluster_local_two_workers(&local_plan, &local_merged);
    let slurm_model = std::fs::read(merged.join("model.ply")).unwrap();
    let local_model = std::fs::read(local_merged.join("model.ply")).unwrap();
    assert!(!slurm_model.is_empty());
    assert!(
        slurm_model == local_model,
        "Slurm's merged model differs from the local engine's"
    );
}
