//! The context of a block plan (issue 43, docs/CLUSTER.md "The context"): a coarse whole-scene
//! run trained once before the blocks. A block trained with it renders the context's Gaussians
//! outside its box frozen — they come out of its training bit for bit as they went in, and only
//! the block's own Gaussians are in its result — and the merge keeps the context's Gaussians
//! outside every block's box beside the blocks' own. A plan without a context is written as
//! before (no `context` field, so its digest is unchanged) and a bad context is refused in one
//! line.

use std::path::Path;

use damage_twin::blocks::block_run::train_block;
use damage_twin::blocks::context_run::context_model_path;
use damage_twin::blocks::plan::{PLAN_FILE, load_plan};
use damage_twin::scene::Dataset;
use damage_twin::scene::open::OpenOptions;
use damage_twin::splats::Splats;
use damage_twin::train::job::{Job, JobOptions};

mod blocks_support;
use blocks_support::{binary, run, tiny_plan, tiny_plan_with};

/// Gaussian `g` of `s` as the bits of every parameter.
fn bits(s: &Splats, g: usize) -> Vec<u32> {
    let mut v: Vec<u32> = s.means[g].to_array().iter().map(|x| x.to_bits()).collect();
    v.extend(s.log_scales[g].to_array().iter().map(|x| x.to_bits()));
    v.extend(s.rotations[g].to_array().iter().map(|x| x.to_bits()));
    v.push(s.raw_opacities[g].to_bits());
    v.extend(s.sh_of(g).iter().map(|x| x.to_bits()));
    v.extend(s.labels_of(g).iter().map(|x| x.to_bits()));
    v
}

/// Every Gaussian of `s` accepted by `keep` (by its centre), as bits, in order.
fn gaussians_where(s: &Splats, keep: impl Fn(glam::Vec3) -> bool) -> Vec<Vec<u32>> {
    (0..s.len())
        .filter(|&g| keep(s.means[g]))
        .map(|g| bits(s, g))
        .collect()
}

fn context_plan(root: &Path) -> std::path::PathBuf {
    tiny_plan_with(
        root,
        "plan",
        &["--context-iters", "40", "--context-scale", "2"],
    )
}

#[test]
fn a_block_renders_the_context_frozen_and_the_merge_keeps_it_outside_every_box() {
    let root = tempfile::tempdir().unwrap();
    let dir = context_plan(root.path());
    let plan = load_plan(&dir).unwrap();
    assert!(plan.context.is_some());

    // A block before its context is a one-line error saying what to run.
    let mut early = binary();
    early
        .arg("train-block")
        .arg(&dir)
        .args(["--block", "0", "--threads", "1", "--quiet"]);
    let output = early.output().unwrap();
    assert!(!output.status.success());
    let error = String::from_utf8_lossy(&output.stderr);
    assert!(
        error.contains("train-block --context") && error.lines().count() == 1,
        "{error}"
    );

    let mut context = binary();
    context
        .arg("train-block")
        .arg(&dir)
        .args(["--context", "--threads", "1"]);
    run(context);
    let model = context_model_path(&dir);
    let before = std::fs::read(&model).unwrap();
    let mut again = binary();
    again.arg("train-block").arg(&dir).args(["--context"]);
    let again = run(again);
    assert!(String::from_utf8_lossy(&again.stdout).contains("already trained"));
    assert_eq!(std::fs::read(&model).unwrap(), before);
    // Blocks start from the context's Gaussians inside their boxes. At 40 steps the context has
    // not densified, so it holds as many there as the initial points: every other one inside
    // block 0's box is dropped, so that the start tells the two apart.
    let context = {
        let mut context = damage_twin::splats::ply::read_splats(&model).unwrap();
        let mut inside = 0;
        let keep: Vec<bool> = context
            .means
            .iter()
            .map(|&p| {
                let trains = plan.trains_point(0, plan.frame.coordinates(p));
                inside += trains as usize;
                !trains || inside % 2 == 0
            })
            .collect();
        context.retain(&keep);
        damage_twin::splats::ply::write_splats(&model, &context).unwrap();
        context
    };

    // Block 0 trained in this process: the context's Gaussians outside its box come out of the
    // run as they went in, bit for bit; its result holds only its own.
    let dataset = Dataset::open(
        &plan.dataset,
        &OpenOptions {
            background: plan.training.background,
        },
    )
    .unwrap();
    let job = {
        let (plan, dir) = (plan.clone(), dir.clone());
        Job::spawn("block", JobOptions::headless(Some(1)), move |ctx| {
            train_block(ctx, &dataset, &plan, &dir, 0)
        })
    };
    let outcome = job.wait().unwrap();
    let frozen = outcome.context.as_ref().expect("trained with the context");
    let outside_block = gaussians_where(&context, |p| {
        !plan.trains_point(0, plan.frame.coordinates(p))
    });
    assert!(!outside_block.is_empty() && outside_block.len() < context.len());
    assert_eq!(
        (0..frozen.len())
            .map(|g| bits(frozen, g))
            .collect::<Vec<_>>(),
        outside_block,
        "the block changed a frozen context Gaussian"
    );
    assert_eq!(outcome.record.context_gaussians, Some(frozen.len()));
    // It started from the context's Gaussians inside its box (a trained start), not from the
    // initial points.
    let inside_block = context.len() - outside_block.len();
    assert_eq!(outcome.record.initial_gaussians, Some(inside_block));
    let own = &outcome.splats;
    assert!(!own.is_empty());
    assert!(
        (0..own.len()).all(|g| !outside_block.contains(&bits(own, g))),
        "a context Gaussian is in the block's own result"
    );

    // The merge: each block's own Gaussians in its box, then the context's outside every box.
    let merged = root.path().join("merged");
    let mut local = binary();
    local
        .args(["cluster", "local"])
        .arg(&dir)
        .args(["--workers", "1", "--threads", "1", "--out"])
        .arg(&merged);
    run(local);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(merged.join("merge.json")).unwrap()).unwrap();
    let outside_all = gaussians_where(&context, |p| {
        plan.outside_every_block(plan.frame.coordinates(p))
    });
    assert!(!outside_all.is_empty());
    assert_eq!(
        report["context"]["kept"].as_u64(),
        Some(outside_all.len() as u64),
        "{report}"
    );
    let model = damage_twin::splats::ply::read_splats(&merged.join("model.ply")).unwrap();
    let from_blocks: u64 = (0..2)
        .map(|k| report["blocks"][k]["kept"].as_u64().unwrap())
        .sum();
    assert_eq!(model.len() as u64, from_blocks + outside_all.len() as u64);
    let tail: Vec<Vec<u32>> = (from_blocks as usize..model.len())
        .map(|g| bits(&model, g))
        .collect();
    assert_eq!(tail, outside_all, "the merge changed the context it kept");
    assert!(
        (0..from_blocks as usize)
            .all(|g| plan.in_structure(plan.frame.coordinates(model.means[g]))),
        "a block kept a Gaussian outside the structure, which is the context's"
    );
}

#[test]
fn a_plan_without_a_context_is_written_as_before_and_a_bad_context_is_refused() {
    let root = tempfile::tempdir().unwrap();
    let dir = tiny_plan(root.path(), "plan");
    let text = std::fs::read_to_string(dir.join(PLAN_FILE)).unwrap();
    assert!(!text.contains("context"), "{text}");
    assert!(load_plan(&dir).unwrap().context.is_none());
    let mut refused = binary();
    refused.arg("train-block").arg(&dir).arg("--context");
    let output = refused.output().unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("no context"));

    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    for (context, field) in [
        (
            serde_json::json!({"iters": 0, "scale": "2"}),
            "context.iters",
        ),
        (
            serde_json::json!({"iters": 5, "scale": "huge"}),
            "context.scale",
        ),
        (serde_json::json!({"iters": 5}), "not a block plan"),
    ] {
        let mut bad = json.clone();
        bad["context"] = context;
        std::fs::write(dir.join(PLAN_FILE), serde_json::to_string(&bad).unwrap()).unwrap();
        let error = load_plan(&dir).expect_err(field).to_string();
        assert!(
            error.contains("plan.json") && error.contains(field) && !error.contains('\n'),
            "{field}: {error}"
        );
    }
}
