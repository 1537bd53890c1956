//! A real Slurm engine: a private single-node cluster (tests/slurm_support) runs an array job of
//! three tasks, each writing its `SLURM_ARRAY_TASK_ID` to its own file (named by the array job's
//! id) and all three arrive; a second array job, submitted without `--wait` and followed by
//! polling, reports exactly its one failing task as failed. Skipped with a printed reason where Slurm cannot
//! start (not root, packages missing), unless `DAMAGE_TWIN_REQUIRE_SLURM=1`.

mod slurm_support;

use slurm_support::SlurmCluster;

#[test]
fn an_array_job_runs_every_task_and_a_failing_task_is_reported() {
    let Some(cluster) = SlurmCluster::start_or_skip("slurm_cluster") else {
        return;
    };
    let out = cluster.dir().join("out");
    std::fs::create_dir(&out).unwrap();
    let script = cluster.dir().join("tasks.sh");
    std::fs::write(
        &script,
        format!(
            "#!/bin/sh\n#SBATCH --job-name=array-test\n#SBATCH --output={out}/slurm-%A_%a.out\n\
             echo \"$SLURM_ARRAY_TASK_ID of $SLURM_ARRAY_TASK_COUNT\" > {out}/task-$SLURM_ARRAY_JOB_ID-$SLURM_ARRAY_TASK_ID\n\
             [ \"$SLURM_ARRAY_TASK_ID\" != \"${{FAIL_TASK:-none}}\" ]\n",
            out = out.display()
        ),
    )
    .unwrap();
    // The failing job is submitted without --wait and followed by polling (as a dependent
    // merge job submitted by an engine script would be), while `sbatch --wait` (which polls at
    // growing intervals, about 10 s here) waits for the good one.
    let started = std::time::Instant::now();
    let plain = cluster
        .command("sbatch")
        .args(["--parsable", "--array=0-2", "--export=ALL,FAIL_TASK=1"])
        .arg(&script)
        .output()
        .unwrap();
    let failing_id: u64 = String::from_utf8_lossy(&plain.stdout)
        .trim()
        .parse()
        .unwrap_or_else(|_| panic!("sbatch: {plain:?}"));
    let job = cluster.submit_and_wait(&script, &["--array=0-2"]);
    let records = cluster
        .wait_for_job(failing_id, std::time::Duration::from_secs(60))
        .unwrap_or_else(|e| panic!("{e}"));
    eprintln!(
        "both array jobs ended in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let job = job.unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(job.exit_code, 0, "{job:?}{}", cluster.logs());
    for task in 0..3 {
        let path = out.join(format!("task-{}-{task}", job.job_id));
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("{}: {e}{}", path.display(), cluster.logs()));
        assert_eq!(text.trim(), format!("{task} of 3"));
    }
    // Exactly the failing task failed, with its exit code 1.
    let mut states: Vec<&str> = records.iter().map(|(state, _)| state.as_str()).collect();
    states.sort_unstable();
    assert_eq!(states, ["COMPLETED", "COMPLETED", "FAILED"], "{records:?}");
    assert!(records.iter().any(|(_, code)| code == "1:0"), "{records:?}");
    assert_ne!(failing_id, job.job_id);
}
