use super::*;

fn write(path: &Path, text: &str) {
    fs::write(path, text).unwrap();
}

#[test]
fn a_new_target_is_created_and_an_old_one_replaced_keeping_the_users_files() {
    let tmp = tempfile::tempdir().unwrap();
    let target = tmp.path().join("run");
    let run = RunFolder::begin(&target, &["model.ply", "metrics.json"]).unwrap();
    write(&run.path("model.ply"), "one");
    run.commit().unwrap();
    assert_eq!(fs::read_to_string(target.join("model.ply")).unwrap(), "one");

    write(&target.join("notes.txt"), "mine");
    fs::create_dir(target.join("renders")).unwrap();
    write(&target.join("renders/a.png"), "png");
    let run = RunFolder::begin(&target, &["model.ply", "metrics.json"]).unwrap();
    write(&run.path("model.ply"), "two");
    write(&run.path("metrics.json"), "{}");
    run.commit().unwrap();
    assert_eq!(fs::read_to_string(target.join("model.ply")).unwrap(), "two");
    assert_eq!(
        fs::read_to_string(target.join("notes.txt")).unwrap(),
        "mine"
    );
    assert_eq!(
        fs::read_to_string(target.join("renders/a.png")).unwrap(),
        "png"
    );
    // Nothing but the target is left beside it.
    assert_eq!(list(tmp.path()).unwrap(), vec!["run".to_string()]);
}

#[cfg(unix)]
#[test]
fn a_link_to_a_folder_replaces_the_folder_it_points_at() {
    let tmp = tempfile::tempdir().unwrap();
    let real = tmp.path().join("real");
    fs::create_dir(&real).unwrap();
    write(&real.join("model.ply"), "old");
    let link = tmp.path().join("link");
    std::os::unix::fs::symlink(&real, &link).unwrap();
    let run = RunFolder::begin(&link, &["model.ply"]).unwrap();
    write(&run.path("model.ply"), "new");
    run.commit().unwrap();
    assert!(
        fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert_eq!(fs::read_to_string(real.join("model.ply")).unwrap(), "new");
}

#[test]
fn leftovers_of_dead_runs_are_cleaned() {
    let tmp = tempfile::tempdir().unwrap();
    let target = tmp.path().join("run");
    fs::create_dir(&target).unwrap();
    write(&target.join("model.ply"), "old");
    // No process has id u32::MAX - 1 on Linux (pid_max is at most 2^22).
    let dead = u32::MAX - 1;
    write(&target.join(format!(".model.ply.{dead}.0.tmp")), "half");
    let stale = tmp.path().join(format!(".run{STAGING_TAG}{dead}"));
    fs::create_dir_all(&stale).unwrap();
    write(&stale.join("model.ply"), "new but never swapped in");

    let run = RunFolder::begin(&target, &["model.ply", "metrics.json"]).unwrap();
    assert!(!stale.exists());
    assert!(!target.join(format!(".model.ply.{dead}.0.tmp")).exists());
    assert_eq!(fs::read_to_string(target.join("model.ply")).unwrap(), "old");
    drop(run);
}

#[test]
fn a_kill_between_the_two_renames_is_repaired_by_the_next_run() {
    let tmp = tempfile::tempdir().unwrap();
    let target = tmp.path().join("run");
    let dead = u32::MAX - 1;
    let old = tmp.path().join(format!(".run{OLD_TAG}{dead}"));
    fs::create_dir(&old).unwrap();
    write(&old.join("model.ply"), "old");
    let _run = RunFolder::begin(&target, &["model.ply", "metrics.json"]).unwrap();
    assert_eq!(fs::read_to_string(target.join("model.ply")).unwrap(), "old");
}

/// A file the run owns and did not write this time (an earlier `--appearance` run's
/// `appearance.json`) is not carried beside the new model; the user's files are.
#[test]
fn a_file_the_run_owns_but_did_not_write_is_not_carried() {
    let tmp = tempfile::tempdir().unwrap();
    let target = tmp.path().join("run");
    let outputs = ["model.ply", "appearance.json", "before_*"];
    let run = RunFolder::begin(&target, &outputs).unwrap();
    write(&run.path("model.ply"), "with appearance");
    write(&run.path("appearance.json"), "[]");
    write(&run.path("before_view-1.png"), "png");
    run.commit().unwrap();
    write(&target.join("notes.txt"), "mine");
    let run = RunFolder::begin(&target, &outputs).unwrap();
    write(&run.path("model.ply"), "without");
    run.commit().unwrap();
    assert_eq!(
        list(&target).unwrap(),
        vec!["model.ply".to_string(), "notes.txt".to_string()]
    );
}

#[test]
fn an_install_is_finished_or_undone_and_a_dead_ones_undone_later() {
    let tmp = tempfile::tempdir().unwrap();
    let target = tmp.path().join("survey");
    fs::create_dir(&target).unwrap();
    write(&target.join("model.ply"), "old");
    write(&target.join("notes.txt"), "mine");
    let run = RunFolder::begin(&target, &["model.ply"]).unwrap();
    write(&run.path("model.ply"), "new");
    let installed = run.install().unwrap();
    assert_eq!(fs::read_to_string(target.join("model.ply")).unwrap(), "new");
    installed.undo();
    assert_eq!(fs::read_to_string(target.join("model.ply")).unwrap(), "old");
    assert_eq!(list(tmp.path()).unwrap(), vec!["survey".to_string()]);

    let run = RunFolder::begin(&target, &["model.ply"]).unwrap();
    write(&run.path("model.ply"), "new");
    run.install().unwrap().finish();
    assert_eq!(fs::read_to_string(target.join("model.ply")).unwrap(), "new");
    assert_eq!(
        fs::read_to_string(target.join("notes.txt")).unwrap(),
        "mine"
    );
    assert_eq!(list(tmp.path()).unwrap(), vec!["survey".to_string()]);

    // What a process killed between the two renames, or after them, left: undone by name.
    let dead = u32::MAX - 1;
    for both_renames in [false, true] {
        let old = tmp.path().join(format!(".survey{OLD_TAG}{dead}"));
        fs::rename(&target, &old).unwrap();
        if both_renames {
            fs::create_dir(&target).unwrap();
            write(&target.join("model.ply"), "newer");
        }
        assert!(has_leftovers(tmp.path()));
        assert_eq!(undo_installs(tmp.path(), dead), vec![target.clone()]);
        clean_leftovers(tmp.path());
        assert_eq!(fs::read_to_string(target.join("model.ply")).unwrap(), "new");
        assert_eq!(list(tmp.path()).unwrap(), vec!["survey".to_string()]);
        assert!(!has_leftovers(tmp.path()));
    }
}

#[test]
fn atomic_temp_names_give_their_pid() {
    assert_eq!(temp_file_pid(".model.ply.4242.7.tmp"), Some(4242));
    assert_eq!(temp_file_pid("model.ply"), None);
    assert_eq!(temp_file_pid(".notes.tmp"), None);
}
