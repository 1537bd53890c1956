//! Survey names are names, not paths (issue 45 §2): a name that climbs out of the project or
//! aliases another survey's folder is refused where it enters (`twin new`, `twin add-survey`, the
//! app's save, a hand-edited `twin.ron`), a `--survey` naming no survey is refused before the file
//! system is touched, and no output path or link of a project leads out of its folder. Each case
//! checks that every file outside the project keeps its bytes. No training: the model is a
//! one-Gaussian PLY.

mod project_support;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use damage_twin::scene::project::PROJECT_FILE;
use damage_twin::timeline::Twin;
use project_support::one_gaussian;

/// Names that are paths, and names a file system folds onto `2024`'s folder.
const PATH_NAMES: &[&str] = &[
    "../../outside",
    "..",
    ".",
    "./2024",
    "2024/",
    "x/../2024",
    "/tmp/survey",
    "2024.",
    "2024 ",
    ".2024",
];

/// A folder with a dataset folder, a model, and `outside/` holding a sentinel file where
/// `surveys/../../outside` would land from a project at `root/projects/p`.
struct Place {
    _temp: tempfile::TempDir,
    root: PathBuf,
}

impl Place {
    fn new() -> Place {
        let temp = tempfile::tempdir().expect("temp folder");
        let root = temp.path().to_path_buf();
        for folder in ["data/2024", "data/2025", "outside", "projects"] {
            std::fs::create_dir_all(root.join(folder)).expect("folder");
        }
        std::fs::write(root.join("outside/model.ply"), b"the user's own file").expect("sentinel");
        damage_twin::splats::ply::write_splats(&root.join("tiny.ply"), &one_gaussian())
            .expect("model");
        Place { _temp: temp, root }
    }

    fn project(&self) -> PathBuf {
        self.root.join("projects/p")
    }

    /// Every file under the root but inside the project, with its bytes.
    fn outside_files(&self) -> BTreeMap<PathBuf, Vec<u8>> {
        let mut files = BTreeMap::new();
        let mut folders = vec![self.root.clone()];
        while let Some(folder) = folders.pop() {
            for entry in std::fs::read_dir(&folder).expect("lists") {
                let path = entry.expect("entry").path();
                if path == self.project() {
                    continue;
                }
                let meta = std::fs::symlink_metadata(&path).expect("stat");
                if meta.is_dir() {
                    folders.push(path);
                } else if meta.is_file() {
                    files.insert(path.clone(), std::fs::read(&path).expect("reads"));
                } else {
                    files.insert(path, Vec::new());
                }
            }
        }
        files
    }

    /// `twin new` with survey 2024 and the tiny model.
    fn new_project(&self, survey: &str) -> Output {
        let (project, data, model) = (
            self.project(),
            self.root.join("data/2024"),
            self.root.join("tiny.ply"),
        );
        cli(&[
            "twin".as_ref(),
            "new".as_ref(),
            project.as_os_str(),
            "--survey".as_ref(),
            survey.as_ref(),
            "--date".as_ref(),
            "2024-06-01".as_ref(),
            "--dataset".as_ref(),
            data.as_os_str(),
            "--model".as_ref(),
            model.as_os_str(),
        ])
    }

    fn twin(&self, command: &str, survey: &str, extra: &[&str]) -> Output {
        let project = self.project();
        let mut args: Vec<&std::ffi::OsStr> = vec![
            "twin".as_ref(),
            command.as_ref(),
            project.as_os_str(),
            "--survey".as_ref(),
            survey.as_ref(),
        ];
        args.extend(extra.iter().map(std::ffi::OsStr::new));
        cli(&args)
    }
}

fn cli(args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_damage-twin"))
        .args(args)
        .env("RAYON_NUM_THREADS", "1")
        .stdin(std::process::Stdio::null())
        .output()
        .expect("runs the binary")
}

/// The command failed (exit 1 or 2) with an error holding every needle, and did not panic.
fn refused(run: &Output, needles: &[&str]) {
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        matches!(run.status.code(), Some(1) | Some(2)),
        "exit {:?}\nstdout: {}\nstderr: {stderr}",
        run.status.code(),
        String::from_utf8_lossy(&run.stdout),
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    let first = stderr.lines().next().unwrap_or_default();
    for needle in needles {
        assert!(first.contains(needle), "{needle:?} not in: {stderr}");
    }
}

fn succeeded(run: &Output) {
    assert!(
        run.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&run.stderr)
    );
}

#[test]
fn twin_new_refuses_path_names_before_making_the_project() {
    let place = Place::new();
    let before = place.outside_files();
    for name in PATH_NAMES {
        let run = place.new_project(name);
        refused(&run, &["--survey", "survey name"]);
        assert!(!place.project().exists(), "{name:?}: the project was made");
        assert_eq!(place.outside_files(), before, "{name:?} wrote outside");
    }
    succeeded(&place.new_project("2024"));
    assert!(place.project().join("surveys/2024/model.ply").is_file());
    assert_eq!(place.outside_files(), before);
}

#[test]
fn add_survey_refuses_path_names_and_aliases_leaving_twin_ron_as_it_was() {
    let place = Place::new();
    succeeded(&place.new_project("2024"));
    let before = place.outside_files();
    let project_file = place.project().join(PROJECT_FILE);
    let saved = std::fs::read(&project_file).expect("twin.ron");
    let dataset = place.root.join("data/2025");
    let dataset = dataset.to_str().expect("a UTF-8 temp path");
    let later = ["--date", "2025-06-01", "--dataset", dataset];
    for name in PATH_NAMES {
        refused(&place.twin("add-survey", name, &later), &["survey name"]);
        assert_eq!(std::fs::read(&project_file).expect("twin.ron"), saved);
    }
    // Differing only in case: one folder on macOS and Windows.
    refused(
        &place.twin("add-survey", "2024", &later),
        &["already exists"],
    );
    succeeded(&place.twin("add-survey", "north", &later));
    refused(
        &place.twin("add-survey", "NORTH", &later),
        &["`north` already exists"],
    );
    assert_eq!(place.outside_files(), before);
}

#[test]
fn unknown_surveys_are_refused_before_anything_is_written() {
    let place = Place::new();
    succeeded(&place.new_project("2024"));
    let project_file = place.project().join(PROJECT_FILE);
    let saved = std::fs::read(&project_file).expect("twin.ron");
    let before = place.outside_files();
    let listing = |dir: &Path| {
        let mut names: Vec<_> = walk(dir);
        names.sort();
        names
    };
    let inside = listing(&place.project());
    for name in ["../../outside", "./2024", "2024/", "x/../2024"] {
        for command in ["detect", "update"] {
            refused(
                &place.twin(command, name, &[]),
                &["no survey named", "twin.ron"],
            );
        }
    }
    assert_eq!(place.outside_files(), before);
    assert_eq!(
        listing(&place.project()),
        inside,
        "nothing new in the project"
    );
    assert_eq!(std::fs::read(&project_file).expect("twin.ron"), saved);
}

/// What `detect` and `update` write for a survey (its model, metrics, history) cannot land outside
/// the project or in another survey's folder: such a survey cannot be added, and a name no survey
/// has writes nothing.
#[test]
fn survey_outputs_cannot_be_named_outside_the_project_or_onto_another_survey() {
    let place = Place::new();
    let mut twin = Twin::create(&place.project()).expect("project");
    twin.add_survey("2024", "2024-06-01", &place.root.join("data/2024"))
        .expect("survey");
    twin.save_model("2024", &one_gaussian()).expect("model");
    twin.save().expect("saves");
    let model = std::fs::read(place.project().join("surveys/2024/model.ply")).expect("model");
    let before = place.outside_files();
    let mut other = one_gaussian();
    other.means[0] = glam::Vec3::ONE;
    for name in ["../../../outside", "./2024", "2024/", "x/../2024"] {
        let added = twin.add_survey(name, "2025-06-01", &place.root.join("data/2025"));
        let error = added.expect_err("a path as a survey name").to_string();
        assert!(error.contains("survey name"), "{error}");
        assert!(twin.save_model(name, &other).is_err(), "{name}");
        assert!(
            twin.save_metrics(name, &serde_json::json!({"psnr": 1.0}))
                .is_err(),
            "{name}"
        );
        assert!(
            twin.save_history(name, &Default::default()).is_err(),
            "{name}"
        );
    }
    assert_eq!(place.outside_files(), before);
    assert_eq!(
        std::fs::read(place.project().join("surveys/2024/model.ply")).expect("model"),
        model,
        "survey 2024's model is as it was"
    );
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).expect("lists") {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            out.extend(walk(&path));
        }
        out.push(path);
    }
    out
}

#[test]
fn a_hand_edited_twin_ron_is_refused_naming_the_field() {
    let place = Place::new();
    succeeded(&place.new_project("2024"));
    let project_file = place.project().join(PROJECT_FILE);
    let good = std::fs::read_to_string(&project_file).expect("twin.ron");
    let before = place.outside_files();
    let edits = [
        ("name: \"2024\"", "name: \"../x\"", "surveys[0].name"),
        ("name: \"2024\"", "name: \"2024/\"", "surveys[0].name"),
        (
            "\"surveys/2024/model.ply\"",
            "\"surveys/../../../outside/model.ply\"",
            "surveys[0].model",
        ),
        (
            "\"surveys/2024/model.ply\"",
            "\"/etc/passwd\"",
            "surveys[0].model",
        ),
        (
            "metrics: None",
            "metrics: Some(\"../../outside/model.ply\")",
            "surveys[0].metrics",
        ),
        (
            "changes: None",
            "changes: Some(\"..\")",
            "surveys[0].changes",
        ),
    ];
    for (from, to, field) in edits {
        assert!(good.contains(from), "{from} not in {good}");
        std::fs::write(&project_file, good.replacen(from, to, 1)).expect("edits");
        for command in ["status", "detect", "update"] {
            let run = if command == "status" {
                let project = place.project();
                cli(&["twin".as_ref(), "status".as_ref(), project.as_os_str()])
            } else {
                place.twin(command, "2024", &[])
            };
            refused(&run, &[PROJECT_FILE, field]);
        }
        assert_eq!(place.outside_files(), before, "{to}");
    }
}

#[test]
fn links_that_leave_the_project_are_refused() {
    let place = Place::new();
    let mut twin = Twin::create(&place.project()).expect("project");
    twin.add_survey("2024", "2024-06-01", &place.root.join("data/2024"))
        .expect("survey");
    twin.save_model("2024", &one_gaussian()).expect("model");
    twin.save().expect("saves");
    let before = place.outside_files();
    let surveys = place.project().join("surveys");
    let outside = place.root.join("outside");

    // The model file a link to a file outside: not read, not written through.
    let model = surveys.join("2024/model.ply");
    std::fs::remove_file(&model).expect("removes");
    std::os::unix::fs::symlink(outside.join("model.ply"), &model).expect("links");
    let error = twin
        .load_model("2024")
        .expect_err("read through a link")
        .to_string();
    assert!(error.contains("outside the project"), "{error}");
    let error = twin
        .save_model("2024", &one_gaussian())
        .expect_err("written through a link")
        .to_string();
    assert!(error.contains("outside the project"), "{error}");

    // The survey folder, then the folder of all surveys, a link out.
    std::fs::remove_dir_all(&surveys).expect("removes");
    std::fs::create_dir(&surveys).expect("folder");
    std::os::unix::fs::symlink(&outside, surveys.join("2024")).expect("links");
    let error = twin
        .save_model("2024", &one_gaussian())
        .expect_err("written through a link")
        .to_string();
    assert!(error.contains("outside the project"), "{error}");
    std::fs::remove_dir_all(&surveys).expect("removes");
    std::os::unix::fs::symlink(&outside, &surveys).expect("links");
    for result in [
        twin.save_model("2024", &one_gaussian()).map(drop),
        twin.save_metrics("2024", &serde_json::json!({"psnr": 1.0}))
            .map(drop),
        twin.load_history("2024").map(drop),
    ] {
        let error = result.expect_err("through a link").to_string();
        assert!(error.contains("outside the project"), "{error}");
    }
    assert_eq!(place.outside_files(), before);

    // A link that stays inside the project is fine.
    std::fs::remove_file(&surveys).expect("removes");
    std::fs::create_dir_all(place.project().join("kept/2024")).expect("folder");
    std::fs::create_dir(&surveys).expect("folder");
    std::os::unix::fs::symlink(place.project().join("kept/2024"), surveys.join("2024"))
        .expect("links");
    twin.save_model("2024", &one_gaussian())
        .expect("a link inside the project");
    assert!(place.project().join("kept/2024/model.ply").is_file());
}

#[test]
fn the_app_names_surveys_after_their_folders_as_plain_names() {
    let place = Place::new();
    let mut twin = Twin::create(&place.project()).expect("project");
    let odd = place.root.join("data/Brücke 2024");
    std::fs::create_dir_all(&odd).expect("folder");
    let first = twin
        .commit(|twin| twin.save_survey_model(Some(&odd), &one_gaussian()))
        .expect("saves");
    assert_eq!(first, "Br-cke-2024");
    let shouting = place.root.join("data/BR-CKE-2024");
    std::fs::create_dir_all(&shouting).expect("folder");
    let second = twin
        .commit(|twin| twin.save_survey_model(Some(&shouting), &one_gaussian()))
        .expect("saves");
    assert_eq!(
        second, "BR-CKE-2024-2",
        "a name differing in case is another's"
    );
    let dots = place.root.join("data/..");
    let third = twin
        .commit(|twin| twin.save_survey_model(Some(&dots), &one_gaussian()))
        .expect("saves");
    assert_eq!(third, "survey");
    for name in [&first, &second, &third] {
        assert!(
            place
                .project()
                .join("surveys")
                .join(name)
                .join("model.ply")
                .is_file()
        );
    }
    Twin::open(&place.project()).expect("reopens");
}
