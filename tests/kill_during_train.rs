//! kill -9 at any moment of `train` (issue 26, §3 "Saves"): the output folder afterwards holds
//! either the previous run's files untouched or the new run's files complete and in step with each
//! other (`metrics.json` describes the `model.ply` and `curve.csv` beside it), the user's own
//! files in it survive, and the next run cleans up what the killed one left beside it.
//!
//! Two kinds of kill: aborts injected at the commit's critical points
//! (`DAMAGE_TWIN_ABORT_AT`, scene::run_folder), and real SIGKILLs at spread-out moments of a
//! run, from start-up to the last write.

mod shared_data;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

fn train(lund: &Path, out: &Path, iters: u32) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_damage-twin"));
    command
        .args(["train"])
        .arg(lund)
        .arg("--out")
        .arg(out)
        .args(["--scale", "w64", "--quiet", "--seed", "3", "--iters"])
        .arg(iters.to_string())
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    command
}

/// Every file in `dir` (recursively) with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let bytes = std::fs::read(&path).unwrap();
                files.insert(path.strip_prefix(dir).unwrap().to_path_buf(), bytes);
            }
        }
    }
    files
}

/// The run's three outputs agree: the model has as many Gaussians as metrics.json says, and the
/// curve ends at its step count. Returns the step count.
fn consistent_run(dir: &Path) -> u64 {
    let metrics: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("metrics.json")).unwrap()).unwrap();
    let model = damage_twin::splats::ply::read_splats(&dir.join("model.ply")).unwrap();
    assert_eq!(metrics["gaussians"].as_u64(), Some(model.len() as u64));
    let iterations = metrics["iterations"].as_u64().unwrap();
    let curve = std::fs::read_to_string(dir.join("curve.csv")).unwrap();
    let last_step: u64 = curve
        .lines()
        .last()
        .and_then(|l| l.split(',').next())
        .and_then(|s| s.parse().ok())
        .unwrap();
    assert_eq!(last_step, iterations, "curve.csv ends at another step");
    iterations
}

/// After a kill: the folder is exactly the previous run (with the user's files) or a complete
/// new run of `new_iters` steps with the user's files.
fn old_or_new(out: &Path, previous: &BTreeMap<PathBuf, Vec<u8>>, new_iters: u64, when: &str) {
    let now = snapshot(out);
    if &now == previous {
        return;
    }
    assert_eq!(
        consistent_run(out),
        new_iters,
        "{when}: neither the previous outputs nor the new ones"
    );
    for user in ["notes.txt", "renders/view.png"] {
        assert_eq!(
            now.get(Path::new(user)),
            previous.get(Path::new(user)),
            "{when}: the user's {user} was lost"
        );
    }
}

/// Only the output folder is left beside it (no staging or replaced folders), and no temporary
/// file inside it.
fn nothing_left_over(parent: &Path, out: &Path) {
    let names: Vec<_> = std::fs::read_dir(parent)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![out.file_name().unwrap().to_os_string()]);
    for name in snapshot(out).keys() {
        assert!(!name.to_string_lossy().ends_with(".tmp"), "{name:?} left");
    }
}

fn first_run(lund: &Path, parent: &Path) -> (PathBuf, BTreeMap<PathBuf, Vec<u8>>) {
    let out = parent.join("run");
    assert!(train(lund, &out, 60).status().unwrap().success());
    std::fs::write(out.join("notes.txt"), "the inspector's notes").unwrap();
    std::fs::create_dir(out.join("renders")).unwrap();
    std::fs::write(out.join("renders/view.png"), "not really a png").unwrap();
    assert_eq!(consistent_run(&out), 60);
    let previous = snapshot(&out);
    (out, previous)
}

#[test]
fn an_abort_at_each_point_of_the_commit_leaves_old_or_new_outputs() {
    let Some(lund) = shared_data::path("opensfm_lund") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (out, previous) = first_run(&lund, tmp.path());
    for point in ["carrying", "before-swap", "after-swap"] {
        let status = train(&lund, &out, 40)
            .env("DAMAGE_TWIN_ABORT_AT", point)
            .status()
            .unwrap();
        assert!(!status.success(), "{point}: the abort did not happen");
        old_or_new(&out, &previous, 40, point);
        let expect_new = point == "after-swap";
        assert_eq!(snapshot(&out) != previous, expect_new, "{point}");
        if expect_new {
            // Put the previous outputs back for the next point.
            std::fs::remove_dir_all(&out).unwrap();
            std::fs::create_dir_all(out.join("renders")).unwrap();
            for (name, bytes) in &previous {
                std::fs::write(out.join(name), bytes).unwrap();
            }
        }
    }
    // The next complete run cleans up what the aborted ones left beside the folder.
    assert!(train(&lund, &out, 40).status().unwrap().success());
    assert_eq!(consistent_run(&out), 40);
    nothing_left_over(tmp.path(), &out);
    assert_eq!(
        std::fs::read(out.join("renders/view.png")).unwrap(),
        b"not really a png"
    );
}

#[test]
fn sigkill_at_spread_out_moments_leaves_old_or_new_outputs() {
    let Some(lund) = shared_data::path("opensfm_lund") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (out, previous) = first_run(&lund, tmp.path());
    // How long a whole run takes here, to spread the kills over it.
    let started = Instant::now();
    let probe = tmp.path().join("probe");
    assert!(train(&lund, &probe, 40).status().unwrap().success());
    let whole = started.elapsed();
    std::fs::remove_dir_all(&probe).unwrap();

    let mut outcomes = (0, 0);
    for k in 0..12u32 {
        // 0 %, 10 %, … 110 % of a run: the last ones land in the writes or after the run.
        let delay = whole.mul_f64(f64::from(k) / 10.0);
        let mut child = train(&lund, &out, 40).spawn().unwrap();
        std::thread::sleep(delay);
        let _ = child.kill();
        let _ = child.wait();
        let when = format!("kill after {} ms", delay.as_millis());
        old_or_new(&out, &previous, 40, &when);
        if snapshot(&out) == previous {
            outcomes.0 += 1;
        } else {
            outcomes.1 += 1;
            // Back to the previous outputs so every kill is judged against them.
            std::fs::remove_dir_all(&out).unwrap();
            std::fs::create_dir_all(out.join("renders")).unwrap();
            for (name, bytes) in &previous {
                std::fs::write(out.join(name), bytes).unwrap();
            }
        }
    }
    eprintln!("kills that left the previous outputs, the new: {outcomes:?}");
    let mut child = train(&lund, &out, 40).spawn().unwrap();
    assert!(child.wait().unwrap().success());
    nothing_left_over(tmp.path(), &out);
}
