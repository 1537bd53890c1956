//! Issue 45 §3: every file a twin project names is read like a hostile input, and values that
//! cannot work are refused before any work. One test per finding; the CLI checks run the binary
//! and require exit status 1 or 2, one error line naming the file or the argument, no
//! "panicked", within `PROMPT` (docs/ROBUSTNESS.md lists each with its cause and fix). No
//! training: a one-Gaussian model over an 8 × 8 `transforms.json` dataset.

mod hostile_support;
mod project_support;

use std::path::{Path, PathBuf};
use std::time::Instant;

use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::project::{ColourTransform, PROJECT_FILE};
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::timeline::Twin;
use damage_twin::train::history::{EvalSample, History, Sample};
#[cfg(target_os = "linux")]
use hostile_support::fifo;
use hostile_support::{PROMPT, Run, args, cli, promptly, refused, transforms_dataset};
use project_support::one_gaussian;
use tempfile::TempDir;

/// A project with one trained-looking survey `s1` (model, metrics, history) over a small dataset.
struct Place {
    _temp: TempDir,
    _data: TempDir,
    dataset: PathBuf,
    project: PathBuf,
}

impl Place {
    fn new() -> Place {
        let temp = tempfile::tempdir().unwrap();
        let data = transforms_dataset();
        let dataset = data.path().to_path_buf();
        let project = temp.path().join("project");
        let mut twin = Twin::create(&project).unwrap();
        twin.add_survey("s1", "2024-01-01", &dataset).unwrap();
        twin.save_model("s1", &one_gaussian()).unwrap();
        twin.save_metrics("s1", &trained_metrics(400.0, 25.0))
            .unwrap();
        twin.save_history("s1", &history(3.0, 0.1)).unwrap();
        twin.project.surveys[0].appearance = Some(ColourTransform {
            offset: [0.25, 0.5, 0.75],
            ..ColourTransform::IDENTITY
        });
        twin.project.settings.metres_per_unit = Some(1.5);
        twin.save().unwrap();
        Place {
            _temp: temp,
            _data: data,
            dataset,
            project,
        }
    }

    fn file(&self, rel: &str) -> PathBuf {
        self.project.join(rel)
    }

    fn out(&self) -> PathBuf {
        self.project.parent().unwrap().join("report")
    }

    fn report(&self) -> Run {
        cli(&args(&[&"report", &self.project, &"--out", &self.out()]))
    }

    /// Replaces `from` by `to` in `twin.ron` (which must hold `from` once).
    fn edit_project(&self, from: &str, to: &str) {
        let path = self.file(PROJECT_FILE);
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text.matches(from).count(), 1, "{from} in {text}");
        std::fs::write(&path, text.replace(from, to)).unwrap();
    }
}

/// A survey's metrics as `twin new` writes them.
fn trained_metrics(seconds: f64, psnr: f64) -> serde_json::Value {
    serde_json::json!({
        "seconds": seconds, "heldout_psnr": psnr, "heldout_ssim": 0.8, "gaussians": 1,
        "iterations": 300, "scale": {"Factor": 1},
    })
}

/// A training history of three samples and one evaluation, `wall` seconds long.
fn history(wall: f64, loss: f64) -> History {
    History {
        samples: (0..3)
            .map(|k| Sample {
                wall_s: wall * (f64::from(k) / 2.0),
                step: k * 100,
                loss: loss / f64::from(k + 1),
                psnr: 20.0 + f64::from(k),
                gaussians: 1 + k as usize,
            })
            .collect(),
        evals: vec![EvalSample {
            wall_s: wall,
            step: 200,
            psnr: 24.0,
        }],
    }
}

/// The command ran to the end promptly, without a panic.
fn completed(run: &Run) {
    assert_eq!(
        run.code,
        Some(0),
        "stdout: {}\nstderr: {}",
        run.stdout,
        run.stderr
    );
    assert!(run.seconds < PROMPT.as_secs_f64(), "took {} s", run.seconds);
}

#[test]
fn a_valid_project_reports() {
    let place = Place::new();
    completed(&place.report());
    let html = std::fs::read_to_string(place.out().join("report.html")).unwrap();
    assert!(html.contains("survey s1: training"), "no training chart");
}

/// A survey's metrics or history replaced by a FIFO (which hung `report`), a folder or a link to
/// nothing (both silently taken for "no history") is refused naming the file.
#[cfg(target_os = "linux")]
#[test]
fn a_survey_file_that_is_not_a_regular_file_is_refused_naming_it() {
    type Swap = fn(&Path);
    let swaps: [(&str, &str, Swap); 4] = [
        ("metrics.json", "named pipe", |p| drop(fifo(p))),
        ("history.json", "named pipe", |p| drop(fifo(p))),
        ("history.json", "a folder", |p| {
            std::fs::create_dir(p).unwrap()
        }),
        // `Twin::inside` counts a dangling link as leading out of the project (issue 45 §2).
        ("history.json", "outside the project", |p| {
            std::os::unix::fs::symlink(p.with_file_name("gone.json"), p).unwrap()
        }),
    ];
    for (name, why, swap) in swaps {
        let place = Place::new();
        let path = place.file(&format!("surveys/s1/{name}"));
        std::fs::remove_file(&path).unwrap();
        swap(&path);
        refused(&place.report(), &[name, why]);
    }
}

/// Values near `f64::MAX`, infinities and NaN in a survey's metrics and history hung plotters'
/// key points in the report's charts; the charts leave out what they cannot place.
#[test]
fn values_near_f64_max_in_metrics_and_history_do_not_hang_the_charts() {
    let place = Place::new();
    let metrics = place.file("surveys/s1/metrics.json");
    let history_file = place.file("surveys/s1/history.json");
    for (seconds, psnr, wall, loss) in [
        (f64::MAX, f64::MAX, f64::MAX, f64::MAX),
        (1e300, -1e300, 1.7e308, -f64::MAX),
        (1e20, 25.0, 1e20, 0.1),
    ] {
        std::fs::write(
            &metrics,
            serde_json::to_string(&trained_metrics(seconds, psnr)).unwrap(),
        )
        .unwrap();
        std::fs::write(
            &history_file,
            serde_json::to_string(&history(wall, loss)).unwrap(),
        )
        .unwrap();
        completed(&place.report());
    }
    // serde_json reads no NaN or inf, but a number past f64::MAX is an error naming the file.
    std::fs::write(&metrics, r#"{"seconds": 1e999}"#).unwrap();
    refused(&place.report(), &["metrics.json"]);
}

/// `settings.metres_per_unit` of −1, NaN or inf panicked in the plane fit and 0 reported no
/// region; a NaN appearance or alignment spread through every render. Each is refused when
/// `twin.ron` loads, naming the field.
#[test]
fn numbers_that_cannot_be_in_twin_ron_are_refused_naming_the_field() {
    for (from, to, field) in [
        (
            "metres_per_unit: Some(1.5)",
            "metres_per_unit: Some(-1.0)",
            "settings.metres_per_unit",
        ),
        (
            "metres_per_unit: Some(1.5)",
            "metres_per_unit: Some(NaN)",
            "settings.metres_per_unit",
        ),
        (
            "metres_per_unit: Some(1.5)",
            "metres_per_unit: Some(inf)",
            "settings.metres_per_unit",
        ),
        (
            "metres_per_unit: Some(1.5)",
            "metres_per_unit: Some(0.0)",
            "settings.metres_per_unit",
        ),
        ("0.75", "NaN", "surveys[0].appearance"),
    ] {
        let place = Place::new();
        place.edit_project(from, to);
        refused(
            &cli(&args(&[&"twin", &"status", &place.project])),
            &[PROJECT_FILE, field],
        );
        let err = Twin::open(&place.project).unwrap_err().to_string();
        assert!(err.contains(field), "{to}: {err}");
    }
}

#[test]
fn set_scale_refuses_a_scale_that_is_no_scale_naming_the_argument() {
    let place = Place::new();
    let before = std::fs::read(place.file(PROJECT_FILE)).unwrap();
    for bad in ["-1", "0", "NaN", "inf"] {
        let value = format!("--metres-per-unit={bad}");
        refused(
            &cli(&args(&[&"twin", &"set-scale", &place.project, &value])),
            &["--metres-per-unit"],
        );
    }
    assert_eq!(std::fs::read(place.file(PROJECT_FILE)).unwrap(), before);
}

/// `export M.ply --out M.ply --format spz` replaced the user's PLY (damage channels and all)
/// with SPZ bytes, which nothing reads back.
#[test]
fn export_refuses_to_write_over_the_model_it_reads() {
    let place = Place::new();
    let model = place.file("surveys/s1/model.ply");
    let before = std::fs::read(&model).unwrap();
    let same_by_another_path = place.file("surveys/../surveys/s1/./model.ply");
    for out in [&model, &same_by_another_path] {
        refused(
            &cli(&args(&[
                &"export",
                &model,
                &"--out",
                out,
                &"--format",
                &"spz",
            ])),
            &["--out", "model.ply", "replace the input"],
        );
    }
    assert_eq!(std::fs::read(&model).unwrap(), before);
}

/// `--threads 100000` spawned threads for minutes before any work.
#[test]
fn absurd_thread_counts_are_refused_naming_the_argument() {
    let place = Place::new();
    let out = place.out();
    let model = place.file("surveys/s1/model.ply");
    for command in [
        args(&[
            &"train",
            &place.dataset,
            &"--out",
            &out,
            &"--threads",
            &"100000",
        ]),
        args(&[
            &"compact",
            &model,
            &place.dataset,
            &"--budget",
            &"1",
            &"--out",
            &out,
            &"--threads",
            &"100000",
        ]),
    ] {
        refused(&cli(&command), &["--threads", "100000"]);
    }
    assert!(!out.exists());
}

/// `report --downscale 1000` measured every survey, then failed on a render of zero width.
#[test]
fn a_report_downscale_beyond_the_limit_is_refused_before_measuring() {
    let place = Place::new();
    refused(
        &cli(&args(&[
            &"report",
            &place.project,
            &"--out",
            &place.out(),
            &"--downscale",
            &"1000",
        ])),
        &["--downscale", "1000"],
    );
    assert!(!place.out().exists());
}

/// `compact --budget 1e-300` wrote a model of no Gaussian and exited 0.
#[test]
fn a_compact_budget_that_keeps_nothing_is_refused_and_nothing_is_written() {
    let place = Place::new();
    let out = place.out().with_extension("ply");
    refused(
        &cli(&args(&[
            &"compact",
            &place.file("surveys/s1/model.ply"),
            &place.dataset,
            &"--budget",
            &"1e-300",
            &"--out",
            &out,
            &"--iters",
            &"0",
        ])),
        &["--budget", "keeps 0"],
    );
    assert!(!out.exists());
}

/// `study … --replot` read its saved JSON with `read_to_string`: a FIFO there hung it.
#[cfg(target_os = "linux")]
#[test]
fn a_study_replot_on_a_fifo_is_refused_at_once() {
    let place = Place::new();
    let out = place.out();
    std::fs::create_dir_all(&out).unwrap();
    fifo(&out.join("budget-study.json"));
    refused(
        &cli(&args(&[
            &"study",
            &"budget",
            &place.dataset,
            &"--scene",
            &"x",
            &"--out",
            &out,
            &"--replot",
        ])),
        &["budget-study.json", "named pipe"],
    );
}

/// A damage mask replaced by a FIFO, a folder or a link to nothing was taken for "no mask"
/// (the view trained as undamaged); docs/ROBUSTNESS.md says it is refused naming the file.
#[cfg(target_os = "linux")]
#[test]
fn a_damage_mask_that_is_not_a_regular_file_is_an_error_naming_it() {
    type Swap = fn(&Path);
    let swaps: [(&str, &str, Swap); 4] = [
        ("masks/crack/f0.png", "named pipe", |p| drop(fifo(p))),
        ("masks/crack/f0.png", "a folder", |p| {
            std::fs::create_dir(p).unwrap()
        }),
        ("masks/crack/f0.png", "does not exist", |p| {
            std::os::unix::fs::symlink(p.with_file_name("gone.png"), p).unwrap()
        }),
        // The colour-coded mask beside the class folders, by the same rule.
        ("masks/f0.png", "named pipe", |p| drop(fifo(p))),
    ];
    for (rel, why, swap) in swaps {
        let data = transforms_dataset();
        let root = data.path().to_path_buf();
        std::fs::create_dir_all(root.join("masks/crack")).unwrap();
        image::GrayImage::from_pixel(8, 8, image::Luma([255]))
            .save(root.join("masks/crack/f0.png"))
            .unwrap();
        let loads = |root: PathBuf| {
            promptly("load_view", move || {
                let dataset = Dataset::open(&root, &OpenOptions::default()).unwrap();
                let index = dataset.views.iter().position(|v| v.name == "f0").unwrap();
                dataset
                    .load_view(index, ImageScale::Factor(1))
                    .map(drop)
                    .map_err(|e| e.to_string())
            })
        };
        assert_eq!(loads(root.clone()), Ok(()), "the valid mask loads");
        let target = root.join(rel);
        if target.exists() {
            std::fs::remove_file(&target).unwrap();
        }
        swap(&target);
        let err = loads(root).unwrap_err();
        assert!(err.contains(rel) && err.contains(why), "{why}: {err}");
        assert!(!err.contains('\n'), "{err}");
    }
}

/// The library call the report, the app's timeline and the fuzz target share returns promptly
/// on a FIFO history, naming it.
#[cfg(target_os = "linux")]
#[test]
fn the_library_refuses_a_fifo_history_promptly() {
    let place = Place::new();
    let path = place.file("surveys/s1/history.json");
    std::fs::remove_file(&path).unwrap();
    fifo(&path);
    let project = place.project.clone();
    let start = Instant::now();
    let err = promptly("load_history", move || {
        Twin::open(&project)
            .unwrap()
            .load_history("s1")
            .unwrap_err()
            .to_string()
    });
    assert!(err.contains("history.json"), "{err}");
    assert!(start.elapsed() < PROMPT);
}
