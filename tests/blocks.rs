//! Block-by-block training (issue 43, docs/CLUSTER.md): the plan file round-trips and bad plans
//! are refused in one line; `cluster local` trains a tiny building's blocks and merges them;
//! a finished block is a no-op; a block SIGKILLed mid-training and rerun gives the same merged
//! model, byte for byte, as an undisturbed run (training is deterministic for a seed: the same
//! bytes at 1 and 2 threads were seen by hand, and this test checks it across processes).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use damage_twin::blocks::plan::{PLAN_FILE, load_plan, save_plan};

mod blocks_support;
use blocks_support::{binary, cluster_local_two_workers, run, tiny_plan};

fn train_block(plan: &Path, k: usize) -> Command {
    let mut command = binary();
    command
        .arg("train-block")
        .arg(plan)
        .args(["--block", &k.to_string(), "--threads", "1"]);
    command
}

/// A change that breaks a plan's JSON.
type Change = dyn Fn(&mut serde_json::Value);

#[test]
fn plan_round_trips_and_bad_plans_are_one_line_refusals() {
    let root = tempfile::tempdir().unwrap();
    let dir = tiny_plan(root.path(), "plan");
    let plan = load_plan(&dir).expect("the written plan loads");
    assert_eq!(plan.blocks.len(), 2);
    assert!(
        plan.blocks
            .iter()
            .all(|b| b.skipped.is_none() && !b.photos.is_empty())
    );
    assert!(dir.join("blocks.png").is_file() && dir.join("block-001/manifest.json").is_file());
    let copy = root.path().join("copy");
    std::fs::create_dir(&copy).unwrap();
    save_plan(&copy, &plan).unwrap();
    assert_eq!(load_plan(&copy).unwrap(), plan);
    assert_eq!(
        load_plan(&copy.join(PLAN_FILE)).unwrap().digest(),
        plan.digest()
    );

    let text = std::fs::read_to_string(dir.join(PLAN_FILE)).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let cases: Vec<(&str, Box<Change>)> = vec![
        ("format", Box::new(|p| p["format"] = "other".into())),
        ("version", Box::new(|p| p["version"] = 99.into())),
        (
            "absolute",
            Box::new(|p| p["dataset"] = "relative/path".into()),
        ),
        (
            "frame.long",
            Box::new(|p| p["frame"]["long"] = serde_json::json!([2.0, 0.0, 0.0])),
        ),
        ("margin", Box::new(|p| p["margin"] = (-1.0).into())),
        (
            "training.scale",
            Box::new(|p| p["training"]["scale"] = "huge".into()),
        ),
        (
            "training.mode",
            Box::new(|p| p["training"]["mode"] = "overlay".into()),
        ),
        (
            "steps_per_photo",
            Box::new(|p| p["training"]["steps_per_photo"] = 0.0.into()),
        ),
        (
            "blocks[1].index",
            Box::new(|p| p["blocks"][1]["index"] = 7.into()),
        ),
        (
            "blocks[1].start",
            Box::new(|p| p["blocks"][1]["start"] = (-1e6).into()),
        ),
        ("blocks", Box::new(|p| p["blocks"] = serde_json::json!([]))),
        ("unknown field", Box::new(|p| p["extra"] = 1.into())),
        (
            "not a block plan",
            Box::new(|p| *p = serde_json::json!({"a": 1})),
        ),
    ];
    for (what, change) in cases {
        let mut bad = json.clone();
        change(&mut bad);
        std::fs::write(copy.join(PLAN_FILE), serde_json::to_string(&bad).unwrap()).unwrap();
        let error = load_plan(&copy).expect_err(what).to_string();
        assert!(error.contains("plan.json"), "{what}: {error}");
        assert!(error.contains(what), "{what}: {error}");
        assert!(!error.contains('\n'), "{what}: {error}");
    }
    std::fs::write(copy.join(PLAN_FILE), "{").unwrap();
    assert!(
        load_plan(&copy)
            .unwrap_err()
            .to_string()
            .contains("not a block plan")
    );
}

/// A leftover staging folder of block `k`'s result (a run that died before its commit).
fn leftovers(plan: &Path, k: usize) -> Vec<PathBuf> {
    std::fs::read_dir(plan.join(format!("block-{k:03}")))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .contains(".staging-")
        })
        .collect()
}

#[test]
fn cluster_local_merges_and_a_killed_block_rerun_gives_the_same_model() {
    let root = tempfile::tempdir().unwrap();
    // The undisturbed run: both blocks on two local workers, then the merge.
    let calm = tiny_plan(root.path(), "calm");
    let merged_calm = root.path().join("merged-calm");
    cluster_local_two_workers(&calm, &merged_calm);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(merged_calm.join("merge.json")).unwrap()).unwrap();
    let gaussians = report["gaussians"].as_u64().unwrap();
    let model = damage_twin::splats::ply::read_splats(&merged_calm.join("model.ply")).unwrap();
    assert_eq!(model.len() as u64, gaussians);
    let kept: u64 = (0..2)
        .map(|k| report["blocks"][k]["kept"].as_u64().unwrap())
        .sum();
    assert_eq!(kept, gaussians);
    for k in 0..2 {
        assert!(
            report["blocks"][k]["kept"].as_u64() < report["blocks"][k]["trained"].as_u64(),
            "block {k} kept its margins: {report}"
        );
    }
    let seam = &report["seam"];
    assert!(seam["band"]["pixels"].as_u64().unwrap() > 0, "{seam}");
    assert!(seam["rest"]["psnr"].as_f64().unwrap() > 10.0, "{seam}");

    // A finished block is a no-op: its result is untouched.
    let result = calm.join("block-000/result/model.ply");
    let before = std::fs::read(&result).unwrap();
    let modified = std::fs::metadata(&result).unwrap().modified().unwrap();
    let again = run(train_block(&calm, 0));
    assert!(String::from_utf8_lossy(&again.stdout).contains("already trained"));
    assert_eq!(std::fs::read(&result).unwrap(), before);
    assert_eq!(
        std::fs::metadata(&result).unwrap().modified().unwrap(),
        modified
    );

    // The disturbed run: block 0 SIGKILLed while it trains, then everything rerun.
    let killed = tiny_plan(root.path(), "killed");
    let mut child = train_block(&killed, 0)
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
    child.kill().unwrap(); // SIGKILL on Unix
    child.wait().unwrap();
    assert!(
        !killed.join("block-000/result").exists(),
        "no result from a killed block"
    );
    assert_eq!(
        leftovers(&killed, 0).len(),
        1,
        "the killed run left its staging folder"
    );
    // The merge names the block that has no result rather than merging a part.
    let mut early = binary();
    early
        .arg("merge")
        .arg(&killed)
        .arg("--out")
        .arg(root.path().join("early"));
    let output = early.output().unwrap();
    assert!(!output.status.success());
    let error = String::from_utf8_lossy(&output.stderr);
    assert!(
        error.contains("block 0 has no finished result") && error.lines().count() == 1,
        "{error}"
    );
    assert!(!root.path().join("early").exists());
    let merged_killed = root.path().join("merged-killed");
    let mut local = binary();
    local
        .args(["cluster", "local"])
        .arg(&killed)
        .args(["--workers", "1", "--out"])
        .arg(&merged_killed);
    run(local);
    assert!(
        leftovers(&killed, 0).is_empty(),
        "the rerun cleaned what the dead run left"
    );
    assert_eq!(
        std::fs::read(merged_killed.join("model.ply")).unwrap(),
        std::fs::read(merged_calm.join("model.ply")).unwrap(),
        "the killed-and-rerun plan merges to another model"
    );
}

#[test]
fn train_block_reads_its_index_from_the_engine_and_refuses_none() {
    let root = tempfile::tempdir().unwrap();
    let plan = tiny_plan(root.path(), "plan");
    let mut none = binary();
    none.arg("train-block").arg(&plan);
    for var in damage_twin::blocks::engines::index::INDEX_VARIABLES {
        none.env_remove(var);
    }
    let output = none.output().unwrap();
    assert!(!output.status.success());
    let error = String::from_utf8_lossy(&output.stderr);
    assert!(
        error.contains("SLURM_ARRAY_TASK_ID") && error.lines().count() == 1,
        "{error}"
    );
    let mut out_of_range = binary();
    out_of_range
        .arg("train-block")
        .arg(&plan)
        .env("JOB_COMPLETION_INDEX", "2");
    let output = out_of_range.output().unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("out of range"));
}
