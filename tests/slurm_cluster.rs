//! A real Slurm engine: a private single-node cluster (tests/slurm_support) runs an array job of
//! three tasks, each writing its `SLURM_ARRAY_TASK_ID` to its own file (named by the array job's
//! id); all three arrive, and a failing task makes `sbatch --wait` fail. Skipped with a printed reason where Slurm cannot
//! start (not root, packages missing), unless `DAMAGE_TWIN_REQUIRE_SLURM=1`.

mod slurm_support;

use slurm_support::SlurmCluster;

#[test]
fn an_array_job_runs_every_task_and_a_failing_task_fails_the_wait() {
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
    // Both jobs at once: `sbatch --wait` polls at growing intervals (about 10 s in all here),
    // so waiting for them in turn would double the test's time.
    let started = std::time::Instant::now();
    let (job, failing) = std::thread::scope(|scope| {
        let good = scope.spawn(|| cluster.submit_and_wait(&script, &["--array=0-2"]));
        let bad = scope.spawn(|| {
            cluster.submit_and_wait(&script, &["--array=0-2", "--export=ALL,FAIL_TASK=1"])
        });
        (good.join().unwrap(), bad.join().unwrap())
    });
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
    // A task that fails makes the whole wait fail: what a cluster runner must notice.
    let failing = failing.unwrap_or_else(|e| panic!("{e}"));
    assert_ne!(failing.exit_code, 0, "{failing:?}");
    assert_ne!(failing.job_id, job.job_id);
}
