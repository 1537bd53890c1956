//! One writer at a time (`timeline::lock`, `Twin::commit`): racing writers of one project lose
//! no record, a held project refuses a second writer naming the holder, a lock file left by a
//! killed process does not block. Quick: no training, a one-Gaussian model.

mod project_support;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::{Arc, Barrier};
use std::time::Duration;

use damage_twin::scene::project::PROJECT_FILE;
use damage_twin::timeline::detect_survey::record_changes;
use damage_twin::timeline::lock::{LOCK_FILE, ProjectLock, Writer};
use damage_twin::timeline::update::commit_update;
use damage_twin::timeline::{TimelineError, Twin};
use project_support::one_gaussian;

const RACES: usize = 50;

/// A project in `dir` with one survey, `base`, dated 2024-01-01.
fn project(dir: &Path) -> PathBuf {
    let project = dir.join("project");
    let mut twin = Twin::create(&project).expect("creates the project");
    twin.add_survey("base", "2024-01-01", &dir.join("data/base"))
        .expect("adds the first survey");
    twin.save().expect("saves the project");
    project
}

fn survey_names(project: &Path) -> Vec<String> {
    Twin::open(project)
        .expect("the project opens")
        .project
        .surveys
        .iter()
        .map(|s| s.name.clone())
        .collect()
}

fn twin_command(args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_damage-twin"));
    command.arg("twin").args(args);
    command
}

fn add_survey(project: &Path, name: &str) -> Command {
    let dataset = project.join("../data").join(name);
    twin_command(&[
        "add-survey",
        &project.to_string_lossy(),
        "--survey",
        name,
        "--date",
        "2024-06-01",
        "--dataset",
        &dataset.to_string_lossy(),
    ])
}

fn text(output: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}

/// The reproducer: two `twin add-survey` on one project at once lost one survey in 10 of
/// 20 tries, both printing success.
#[test]
fn racing_add_surveys_lose_no_survey() {
    let dir = tempfile::tempdir().expect("temp dir");
    for race in 0..RACES {
        let project = project(&dir.path().join(format!("race-{race}")));
        let first = add_survey(&project, "a")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("starts add-survey a");
        let second = add_survey(&project, "b")
            .output()
            .expect("runs add-survey b");
        let first = first.wait_with_output().expect("add-survey a ends");
        assert!(first.status.success(), "race {race}: {}", text(&first));
        assert!(second.status.success(), "race {race}: {}", text(&second));
        let mut names = survey_names(&project);
        names.sort();
        assert_eq!(names, ["a", "b", "base"], "race {race}: a survey was lost");
    }
}

/// `twin update` reads the project when it starts and records its result when it ends: a survey
/// added meanwhile stays, and the update's own record is written. The same for a detection's
/// record and a scale set meanwhile.
#[test]
fn a_long_jobs_commit_keeps_what_others_wrote_meanwhile() {
    let dir = tempfile::tempdir().expect("temp dir");
    let project = project(dir.path());
    let mut adding = Twin::open(&project).expect("opens");
    adding
        .add_survey("2025", "2025-01-01", &dir.path().join("data/2025"))
        .expect("adds");
    adding.save().expect("saves");

    // Both jobs read the project now; others write before they end.
    let mut updating = Twin::open(&project).expect("opens");
    let mut detecting = Twin::open(&project).expect("opens");
    let mut other = Twin::open(&project).expect("opens");
    other
        .commit(|twin| {
            twin.add_survey("2026", "2026-01-01", &dir.path().join("data/2026"))?;
            twin.project.settings.metres_per_unit = Some(0.5);
            Ok(())
        })
        .expect("another command commits");

    let report = serde_json::json!({"survey": "2025", "psnr": 30.0});
    commit_update(&mut updating, "2025", &one_gaussian(), &report, None, None)
        .expect("update commits");
    let folder = updating
        .survey_dir("2025")
        .expect("survey 2025 exists")
        .join("changes");
    record_changes(&mut detecting, "2025", &folder).expect("detection commits");

    let back = Twin::open(&project).expect("opens");
    let names: Vec<_> = back
        .project
        .surveys
        .iter()
        .map(|s| s.name.as_str())
        .collect();
    assert_eq!(
        names,
        ["base", "2025", "2026"],
        "the survey added meanwhile stays"
    );
    assert_eq!(back.project.settings.metres_per_unit, Some(0.5));
    let updated = back.survey("2025").expect("survey 2025");
    assert!(updated.model.is_some() && updated.metrics.is_some());
    assert!(updated.changes.is_some());
    assert_eq!(
        updating.project.surveys.len(),
        3,
        "the job sees the project as committed"
    );
}

/// Fifty races of an update's commit against an `add-survey` commit, both having read the
/// project before either wrote.
#[test]
fn racing_update_and_add_survey_commits_keep_both() {
    let dir = tempfile::tempdir().expect("temp dir");
    let model = Arc::new(one_gaussian());
    for race in 0..RACES {
        let root = dir.path().join(format!("race-{race}"));
        let project = project(&root);
        let both_read = Arc::new(Barrier::new(2));
        let update = {
            let (project, both_read, model) = (project.clone(), both_read.clone(), model.clone());
            std::thread::spawn(move || {
                let mut twin = Twin::open(&project).expect("opens");
                both_read.wait();
                let report = serde_json::json!({"survey": "base"});
                commit_update(&mut twin, "base", &model, &report, None, None).map(|_| ())
            })
        };
        let mut twin = Twin::open(&project).expect("opens");
        both_read.wait();
        let added = twin.commit(|twin| {
            twin.add_survey("later", "2025-01-01", &root.join("data/later"))
                .map(|_| ())
        });
        added.expect("add-survey commits");
        update.join().expect("no panic").expect("update commits");
        let back = Twin::open(&project).expect("opens");
        assert_eq!(
            back.project.surveys.len(),
            2,
            "race {race}: a survey was lost"
        );
        assert!(
            back.survey("base").expect("base").model.is_some(),
            "race {race}: the update's record was lost"
        );
    }
}

/// A whole-file save over a project another command changed since it was read is refused, and
/// the other command's record stays.
#[test]
fn a_save_over_another_writers_change_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let project = project(dir.path());
    let mut stale = Twin::open(&project).expect("opens");
    let mut other = Twin::open(&project).expect("opens");
    other
        .commit(|twin| {
            twin.project.settings.metres_per_unit = Some(2.0);
            Ok(())
        })
        .expect("commits");
    stale.project.settings.background = [1.0; 3];
    let error = stale.save().expect_err("a stale save is refused");
    assert!(matches!(error, TimelineError::Changed { .. }), "{error}");
    assert!(error.to_string().contains(PROJECT_FILE), "{error}");
    let back = Twin::open(&project).expect("opens");
    assert_eq!(back.project.settings.metres_per_unit, Some(2.0));
    // A new project where another appeared meanwhile is refused too.
    let mut late = Twin::create(&dir.path().join("second")).expect("creates");
    project_in(&dir.path().join("second"));
    assert!(matches!(late.save(), Err(TimelineError::Exists { .. })));
}

fn project_in(dir: &Path) {
    let mut twin = Twin::create(dir).expect("creates");
    twin.save().expect("saves");
}

/// While another process holds the project, a writer waits for `--lock-wait`, then refuses,
/// naming the holder; the project stays as it was.
#[test]
fn a_held_project_refuses_a_second_writer_naming_the_holder() {
    let dir = tempfile::tempdir().expect("temp dir");
    let project = project(dir.path());
    let before = std::fs::read(project.join(PROJECT_FILE)).expect("reads twin.ron");
    let held = ProjectLock::acquire(&project, &Writer::new("twin update")).expect("locks");
    let output = twin_command(&[
        "set-scale",
        &project.to_string_lossy(),
        "--metres-per-unit",
        "2",
        "--lock-wait",
        "0.3",
    ])
    .output()
    .expect("runs set-scale");
    let message = text(&output);
    assert!(!output.status.success(), "{message}");
    let holder = format!(
        "project is being updated by `twin update` (pid {})",
        std::process::id()
    );
    assert!(message.contains(&holder), "{message}");
    assert!(
        message.contains("waiting up to 0.3 s"),
        "told it waits: {message}"
    );
    assert!(message.contains("try again when it finishes"), "{message}");
    assert_eq!(std::fs::read(project.join(PROJECT_FILE)).unwrap(), before);

    // The app's saves and the library's commits refuse the same way.
    let mut twin = Twin::open(&project)
        .expect("opens")
        .with_writer(Writer::new("test").waiting(Duration::from_millis(100)));
    let error = twin.commit(|_| Ok(())).expect_err("refused while held");
    assert!(error.to_string().contains("`twin update`"), "{error}");
    drop(held);
    twin.commit(|_| Ok(())).expect("commits once released");
}

/// A lock file left by a killed process (its holder's name still in it, no OS lock held) does
/// not block the next writer.
#[test]
fn a_lock_file_left_by_a_killed_process_does_not_block() {
    let dir = tempfile::tempdir().expect("temp dir");
    let project = project(dir.path());
    std::fs::write(
        project.join(LOCK_FILE),
        "command: twin update\npid: 999999\nsince: 1700000000\n",
    )
    .expect("writes a stale lock file");
    let output = twin_command(&[
        "set-scale",
        &project.to_string_lossy(),
        "--metres-per-unit",
        "2",
        "--lock-wait",
        "0",
    ])
    .output()
    .expect("runs set-scale");
    assert!(output.status.success(), "{}", text(&output));
    let back = Twin::open(&project).expect("opens");
    assert_eq!(back.project.settings.metres_per_unit, Some(2.0));
}
