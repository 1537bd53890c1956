//! Shared by the block tests (`tests/blocks.rs`, `tests/slurm_blocks.rs`, `tests/twin_blocks.rs`):
//! the binary, a run that must succeed, a tiny demo building partitioned into two blocks, and a
//! plan's blocks trained and merged by `cluster local`.

// Each test binary uses only some of these helpers.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn binary() -> Command {
    Command::new(env!("CARGO_BIN_EXE_damage-twin"))
}

pub fn run(mut command: Command) -> Output {
    let output = command.output().expect("runs");
    assert!(
        output.status.success(),
        "{command:?} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// `cluster local PLAN --workers 2 --threads 1 --out MERGED`, which must succeed.
pub fn cluster_local_two_workers(plan: &Path, merged: &Path) {
    let mut local = binary();
    local
        .args(["cluster", "local"])
        .arg(plan)
        .args(["--workers", "2", "--threads", "1", "--out"])
        .arg(merged);
    run(local);
}

/// A tiny demo building (96×54, 16 views) and a 2-block plan of it in `root/plan`.
pub fn tiny_plan(root: &Path, plan: &str) -> PathBuf {
    tiny_plan_with(root, plan, &[])
}

/// `tiny_plan` with more `partition` flags (`extra`).
pub fn tiny_plan_with(root: &Path, plan: &str, extra: &[&str]) -> PathBuf {
    let synth = root.join("synth");
    if !synth.exists() {
        let params = damage_twin::synth::SynthParams {
            width: 96,
            height: 54,
            views: 16,
            surveys: 1,
            sparse_points: 1500,
            ..damage_twin::synth::SynthParams::demo(synth.clone())
        };
        damage_twin::synth::generate(&params, &|_, _| {}).expect("synth");
    }
    let out = root.join(plan);
    partition_in_two(&synth.join("survey-1"), &out, "80", extra);
    out
}

/// `partition DATASET --out OUT --blocks 2 --iters ITERS --seed 5` with the `extra` flags.
pub fn partition_in_two(dataset: &Path, out: &Path, iters: &str, extra: &[&str]) {
    let mut partition = binary();
    partition
        .arg("partition")
        .arg(dataset)
        .arg("--out")
        .arg(out)
        .args(["--blocks", "2", "--iters", iters, "--seed", "5"])
        .args(extra);
    run(partition);
}
