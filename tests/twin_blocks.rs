//! The timeline on a partitioned twin (issue 43 §6, docs/CLUSTER.md): a tiny two-span bridge
//! partitioned into two blocks, trained, merged and made a twin with `twin new --plan`; survey 2
//! (new damage on one span) added; `twin detect` attributes its changes to blocks; `twin update`
//! retrains only the named block through the local engine, keeps the other block's Gaussians as
//! they were and leaves the first plan's files untouched; a rerun is a no-op, and a block killed
//! mid-training then rerun gives the same model as an undisturbed update.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use damage_twin::blocks::load_plan;
use damage_twin::splats::Splats;
use damage_twin::splats::ply::read_splats;

mod blocks_support;
use blocks_support::{binary, cluster_local_two_workers, partition_in_two, run};

/// A two-span bridge at 96×54 (survey 1: 24 views; survey 2: 12, new damage on one span).
fn tiny_bridge(root: &Path) -> PathBuf {
    let out = root.join("bridge");
    let params = damage_twin::synth::SynthParams {
        width: 96,
        height: 54,
        views: 24,
        views_survey2: 12,
        sparse_points: 1500,
        ..damage_twin::synth::SynthParams::bridge(&out, 2)
    };
    damage_twin::synth::generate(&params, &|_, _| {}).expect("synth");
    out
}

/// Every file under `dir` with its bytes and modification time.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, (Vec<u8>, std::time::SystemTime)> {
    let mut files = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let modified = std::fs::metadata(&path).unwrap().modified().unwrap();
                files.insert(path.clone(), (std::fs::read(&path).unwrap(), modified));
            }
        }
    }
    files
}

/// A twin project `root/name` of survey 1's merged model (recorded with its plan) and survey 2.
fn project(root: &Path, name: &str, bridge: &Path, plan: &Path, merged: &Path) -> PathBuf {
    let dir = root.join(name);
    let mut new = binary();
    new.args(["twin", "new"])
        .arg(&dir)
        .args(["--survey", "survey-1", "--date", "2024-05-01", "--dataset"])
        .arg(bridge.join("survey-1"))
        .arg("--model")
        .arg(merged.join("model.ply"))
        .arg("--plan")
        .arg(plan)
        .args(["--scale", "1"]);
    run(new);
    let mut add = binary();
    add.args(["twin", "add-survey"])
        .arg(&dir)
        .args(["--survey", "survey-2", "--date", "2025-05-01", "--dataset"])
        .arg(bridge.join("survey-2"));
    run(add);
    dir
}

/// Runs `command`, which must fail with one line of error output holding `expected`.
fn refused(mut command: Command, expected: &str) {
    let output = command.output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{command:?} succeeded");
    assert!(stderr.contains(expected), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
}

fn update(dir: &Path, blocks: &str) -> Command {
    let mut command = binary();
    command
        .args(["twin", "update"])
        .arg(dir)
        .args(["--survey", "survey-2", "--blocks", blocks, "--quiet"]);
    command
}

/// The Gaussians of `model` whose centres lie in block `k`'s own box, without their ids.
fn block_part(model: &Splats, plan: &damage_twin::blocks::Plan, k: usize) -> Vec<String> {
    (0..model.len())
        .filter(|&g| plan.keeps(k, plan.frame.coordinates(model.means[g]).x))
        .map(|g| {
            format!(
                "{:?} {:?} {:?} {:?} {:?} {:?} {} {} {:?}",
                model.means[g],
                model.log_scales[g],
                model.rotations[g],
                model.raw_opacities[g],
                model.sh_of(g),
                model.labels_of(g),
                model.meta.survey[g],
                model.meta.damage_survey[g],
                model.meta.state[g],
            )
        })
        .collect()
}

/// The tiny bridge's survey 1 partitioned into `ROOT/plan` (two blocks, 60 steps, seed 5, and
/// the `extra` flags).
fn partition_bridge(root: &Path, bridge: &Path, extra: &[&str]) -> PathBuf {
    let plan = root.join("plan");
    partition_in_two(&bridge.join("survey-1"), &plan, "60", extra);
    plan
}

#[test]
fn a_partitioned_twin_updates_only_its_changed_blocks() {
    let root = tempfile::tempdir().unwrap();
    let bridge = tiny_bridge(root.path());
    let plan = partition_bridge(root.path(), &bridge, &[]);
    let merged = root.path().join("merged");
    cluster_local_two_workers(&plan, &merged);
    let first_plan = snapshot(&plan);

    // A plan of another survey's dataset is refused.
    let mut other = binary();
    other
        .args(["twin", "new"])
        .arg(root.path().join("other"))
        .args(["--survey", "s2", "--date", "2025-05-01", "--dataset"])
        .arg(bridge.join("survey-2"))
        .arg("--model")
        .arg(merged.join("model.ply"))
        .arg("--plan")
        .arg(&plan);
    refused(other, "the plan is of");

    // Detection says which blocks changed, attributing every changed pixel it can place.
    let calm = project(root.path(), "calm", &bridge, &plan, &merged);
    let mut detect = binary();
    detect
        .args(["twin", "detect"])
        .arg(&calm)
        .args(["--survey", "survey-2", "--json"]);
    let summary: serde_json::Value = serde_json::from_slice(&run(detect).stdout).unwrap();
    let blocks = summary["blocks"]["blocks"]
        .as_array()
        .expect("changes per block");
    assert_eq!(blocks.len(), 2, "{summary}");
    let new_pixels: u64 = blocks
        .iter()
        .map(|b| b["new_pixels"].as_u64().unwrap())
        .sum();
    let raw_new: u64 = summary["new_damage"]
        .as_object()
        .unwrap()
        .values()
        .map(|f| f["pixels"].as_u64().unwrap())
        .sum();
    eprintln!("detect: {}", summary["blocks"]);
    assert!(new_pixels > 0, "{summary}");
    assert!(new_pixels <= raw_new, "{new_pixels} > {raw_new}");

    // The update retrains block 1 only.
    let out = run(update(&calm, "1"));
    eprintln!("{}", String::from_utf8_lossy(&out.stdout));
    let plan2 = calm.join("blocks/survey-2");
    assert!(plan2.join("block-001/result/model.ply").is_file());
    assert!(
        !plan2.join("block-000/result").exists(),
        "the unchanged block was trained"
    );
    assert_eq!(
        snapshot(&plan),
        first_plan,
        "the first plan's files changed"
    );
    let plan2_loaded = load_plan(&plan2).unwrap();
    assert!(plan2_loaded.blocks[0].skipped.is_some());
    assert!(plan2_loaded.blocks[1].skipped.is_none());
    let before = read_splats(&calm.join("surveys/survey-1/model.ply")).unwrap();
    let after_path = calm.join("surveys/survey-2/model.ply");
    let after = read_splats(&after_path).expect("the updated model opens");
    let first = load_plan(&plan).unwrap();
    assert_eq!(
        block_part(&after, &first, 0),
        block_part(&before, &first, 0),
        "block 0's Gaussians were not kept as they were"
    );
    assert_ne!(
        block_part(&after, &first, 1),
        block_part(&before, &first, 1)
    );
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(calm.join("surveys/survey-2/blocks.json")).unwrap())
            .unwrap();
    assert_eq!(record["trained"], serde_json::json!([1]), "{record}");
    assert_eq!(record["kept"], serde_json::json!([0]), "{record}");
    assert_eq!(record["previous"], "survey-1");

    // A rerun retrains nothing and records the same model.
    let bytes = std::fs::read(&after_path).unwrap();
    let trained = snapshot(&plan2.join("block-001"));
    run(update(&calm, "1"));
    assert_eq!(snapshot(&plan2.join("block-001")), trained);
    assert_eq!(std::fs::read(&after_path).unwrap(), bytes);

    // Block 1 of another project SIGKILLed while it trains, then the update rerun. Before it:
    // with no detection and no --blocks the update is refused in one line.
    let killed = project(root.path(), "killed", &bridge, &plan, &merged);
    let mut undetected = binary();
    undetected
        .args(["twin", "update"])
        .arg(&killed)
        .args(["--survey", "survey-2", "--quiet"]);
    refused(undetected, "run `twin detect --survey survey-2` first");
    let mut slurm = update(&killed, "1");
    slurm.args(["slurm", "--cpus", "2"]);
    let written = run(slurm);
    let plan_killed = killed.join("blocks/survey-2");
    let finish = std::fs::read_to_string(plan_killed.join("slurm/merge.sbatch")).unwrap();
    assert!(
        finish.contains("twin update") && finish.contains("--blocks=1"),
        "{finish}\n{}",
        String::from_utf8_lossy(&written.stdout)
    );
    let mut child = binary()
        .arg("train-block")
        .arg(&plan_killed)
        .args(["--block", "1", "--threads", "1"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = BufReader::new(child.stderr.take().unwrap());
    for line in stderr.lines() {
        if line.unwrap().starts_with("training ") {
            break;
        }
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!plan_killed.join("block-001/result").exists());
    run(update(&killed, "1"));
    assert_eq!(
        std::fs::read(killed.join("surveys/survey-2/model.ply")).unwrap(),
        bytes,
        "the killed-and-rerun update gives another model"
    );
}

#[test]
fn a_partitioned_twin_with_a_context_updates_its_changed_blocks_without_one() {
    // The twin's model merged from blocks trained with a context; the update's plan drops the
    // context (it is of survey 1's photos), trains block 1 on survey 2 alone and keeps block 0's
    // part of the model — the context's Gaussians there with it — as it was.
    let root = tempfile::tempdir().unwrap();
    let bridge = tiny_bridge(root.path());
    let plan = partition_bridge(
        root.path(),
        &bridge,
        &["--context-iters", "40", "--context-scale", "2"],
    );
    let merged = root.path().join("merged");
    cluster_local_two_workers(&plan, &merged);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(merged.join("merge.json")).unwrap()).unwrap();
    assert!(report["context"]["kept"].as_u64() > Some(0), "{report}");
    let dir = project(root.path(), "twin", &bridge, &plan, &merged);
    let mut detect = binary();
    detect
        .args(["twin", "detect"])
        .arg(&dir)
        .args(["--survey", "survey-2", "--json"]);
    run(detect);
    run(update(&dir, "1"));
    let plan2 = load_plan(&dir.join("blocks/survey-2")).unwrap();
    assert!(plan2.context.is_none());
    assert!(plan2.blocks[0].skipped.is_some());
    let before = read_splats(&dir.join("surveys/survey-1/model.ply")).unwrap();
    let after = read_splats(&dir.join("surveys/survey-2/model.ply")).unwrap();
    let first = load_plan(&plan).unwrap();
    assert!(first.context.is_some());
    let kept = block_part(&before, &first, 0);
    assert!(
        (0..before.len()).any(|g| {
            let p = first.frame.coordinates(before.means[g]);
            first.keeps(0, p.x) && !first.in_structure(p)
        }),
        "no context Gaussian lies in block 0's part"
    );
    assert_eq!(block_part(&after, &first, 0), kept);
}
