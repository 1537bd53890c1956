//! A twin commit is all or nothing (issue 45 §4, `timeline::twin::staging`): what a command
//! killed half-way through a commit left is rolled back (before the project file's rename) or
//! cleaned (after it) by the next command, temporary files of killed writers do not stay, and
//! `twin detect` writes its change maps under the project's lock. Quick: no training.

mod project_support;

use std::path::{Path, PathBuf};
use std::time::Duration;

use damage_twin::scene::project::PROJECT_FILE;
use damage_twin::timeline::Twin;
use damage_twin::timeline::detect_survey::{DetectOptions, detect_survey};
use damage_twin::timeline::lock::{ProjectLock, Writer};
use project_support::{gaussians, one_gaussian};

/// No process has this id on Linux (pid_max is at most 2^22): what a killed process left.
const DEAD: u32 = u32::MAX - 1;

/// A project with surveys `a` and `b`, `b` with a model of one Gaussian, metrics and history.
fn project(root: &Path) -> PathBuf {
    let dir = root.join("project");
    let mut twin = Twin::create(&dir).unwrap();
    twin.add_survey("a", "2024-01-01", &root.join("data/a"))
        .unwrap();
    twin.add_survey("b", "2025-01-01", &root.join("data/b"))
        .unwrap();
    twin.commit(|twin| {
        twin.save_model("a", &one_gaussian())?;
        twin.save_model("b", &one_gaussian())?;
        twin.save_metrics("b", &serde_json::json!({"run": "old"}))?;
        twin.save_history("b", &Default::default()).map(drop)
    })
    .unwrap();
    dir
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The survey folder `b` as a commit killed after installing it leaves it: the new folder in
/// place, the previous aside, and (`committed` false) the new project file not yet renamed.
fn killed_commit(dir: &Path, committed: bool) {
    // Read before the leftovers exist (opening would clean them).
    let mut project = Twin::open(dir).unwrap().project;
    let surveys = dir.join("surveys");
    let old = surveys.join(format!(".b.replaced-{DEAD}"));
    std::fs::rename(surveys.join("b"), &old).unwrap();
    std::fs::create_dir(surveys.join("b")).unwrap();
    damage_twin::splats::ply::write_splats(&surveys.join("b/model.ply"), &gaussians(2)).unwrap();
    std::fs::write(surveys.join("b/metrics.json"), r#"{"run": "new"}"#).unwrap();
    project.surveys[1].appearance = Some(damage_twin::scene::project::ColourTransform::IDENTITY);
    let pending = project.save_pending(&dir.join(PROJECT_FILE)).unwrap();
    if committed {
        pending.commit().unwrap();
    } else {
        // The process was killed here: its temporary project file stays, named with its id.
        let temp = dir.join(format!(".{PROJECT_FILE}.{DEAD}.0.tmp"));
        let live = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.to_string_lossy().ends_with(".tmp"))
            .unwrap();
        std::fs::copy(&live, &temp).unwrap();
        drop(pending);
    }
}

fn leftovers(dir: &Path) -> Vec<String> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if name.contains(".staging-") || name.contains(".replaced-") || name.ends_with(".tmp") {
                found.push(name);
            }
            if path.is_dir() {
                stack.push(path);
            }
        }
    }
    found
}

#[test]
fn a_commit_killed_before_its_project_file_is_rolled_back_by_the_next_command() {
    let root = tempfile::tempdir().unwrap();
    let dir = project(root.path());
    let before_model = read(&dir.join("surveys/b/model.ply"));
    let before_project = read(&dir.join(PROJECT_FILE));
    killed_commit(&dir, false);
    let twin = Twin::open(&dir).unwrap();
    assert!(!twin.recovered().is_empty(), "the cleaning is reported");
    assert!(
        read(&dir.join("surveys/b/model.ply")) == before_model,
        "not rolled back"
    );
    assert_eq!(
        read(&dir.join("surveys/b/metrics.json")),
        br#"{
  "run": "old"
}"#
    );
    assert!(dir.join("surveys/b/history.json").is_file());
    assert!(read(&dir.join(PROJECT_FILE)) == before_project);
    assert_eq!(leftovers(&dir), Vec::<String>::new());
}

#[test]
fn a_commit_killed_after_its_project_file_keeps_the_new_state() {
    let root = tempfile::tempdir().unwrap();
    let dir = project(root.path());
    killed_commit(&dir, true);
    let twin = Twin::open(&dir).unwrap();
    assert!(!twin.recovered().is_empty());
    assert_eq!(twin.load_model("b").unwrap().unwrap().len(), 2);
    assert!(twin.survey("b").unwrap().appearance.is_some());
    assert_eq!(leftovers(&dir), Vec::<String>::new());
}

/// The issue's reproducer: kill -9 at the model's fsync during `twin update` left
/// `.model.ply.<pid>.0.tmp` that nothing removed.
#[test]
fn temporary_files_of_a_killed_writer_are_removed_by_the_next_command() {
    let root = tempfile::tempdir().unwrap();
    let dir = project(root.path());
    let temp = dir.join(format!("surveys/b/.model.ply.{DEAD}.0.tmp"));
    std::fs::write(&temp, b"half a model").unwrap();
    let staging = dir.join(format!("surveys/.b.staging-{DEAD}"));
    std::fs::create_dir(&staging).unwrap();
    std::fs::write(staging.join("model.ply"), b"never committed").unwrap();
    let mut twin = Twin::open(&dir).unwrap();
    assert!(!temp.exists() && !staging.exists());
    assert_eq!(twin.recovered().len(), 2);
    // A commit cleans too (a writer killed after this one opened the project).
    std::fs::write(&temp, b"half a model").unwrap();
    twin.commit(|_| Ok(())).unwrap();
    assert!(!temp.exists());
    assert_eq!(leftovers(&dir), Vec::<String>::new());
}

/// A commit's new files replace the survey's previous ones, none of which stays beside them.
#[test]
fn an_update_commit_leaves_no_history_of_the_previous_update() {
    let root = tempfile::tempdir().unwrap();
    let dir = project(root.path());
    let mut twin = Twin::open(&dir).unwrap();
    let report = serde_json::json!({"run": "new"});
    damage_twin::timeline::update::commit_update(
        &mut twin,
        "b",
        &gaussians(3),
        &report,
        None,
        None,
    )
    .unwrap();
    assert_eq!(twin.load_model("b").unwrap().unwrap().len(), 3);
    assert!(
        !dir.join("surveys/b/history.json").exists(),
        "the previous update's history.json stayed beside the new model"
    );
    assert_eq!(leftovers(&dir), Vec::<String>::new());
}

/// `twin detect` used to write its change maps before taking the lock: a detection refused by
/// another writer had already replaced them.
#[test]
fn a_detection_refused_the_lock_writes_no_change_map() {
    let root = tempfile::tempdir().unwrap();
    let params = damage_twin::synth::SynthParams {
        width: 48,
        height: 27,
        views: 3,
        views_survey2: 3,
        surveys: 2,
        sparse_points: 100,
        ..damage_twin::synth::SynthParams::demo(root.path().join("synth"))
    };
    damage_twin::synth::generate(&params, &|_, _| {}).expect("synth");
    let dir = root.path().join("project");
    let mut twin = Twin::create(&dir).unwrap();
    twin.add_survey("a", "2024-01-01", &root.path().join("synth/survey-1"))
        .unwrap();
    twin.add_survey("b", "2025-01-01", &root.path().join("synth/survey-2"))
        .unwrap();
    twin.commit(|twin| twin.save_model("a", &gaussians(4)).map(drop))
        .unwrap();
    let held = ProjectLock::acquire(&dir, &Writer::new("twin update")).unwrap();
    let mut detecting = twin.with_writer(Writer::new("twin detect").waiting(Duration::ZERO));
    let options = DetectOptions::default();
    let error = detect_survey(&mut detecting, "b", &options, &mut |_, _| {}).unwrap_err();
    assert!(error.to_string().contains("twin update"), "{error}");
    assert!(
        !dir.join("surveys/b/changes").exists(),
        "change maps written without the lock"
    );
    drop(held);
    let summary = detect_survey(&mut detecting, "b", &options, &mut |_, _| {}).unwrap();
    assert_eq!(summary.views, 3);
    assert!(dir.join("surveys/b/changes/changes.json").is_file());
    assert_eq!(leftovers(&dir), Vec::<String>::new());
}
