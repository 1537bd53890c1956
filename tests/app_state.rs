//! The viewer's state driven headless through commands, as panels drive it: settings edits and
//! their persistence, snapping to survey views, saving and reopening a twin, exporting, and the
//! charts' history.
#![cfg(feature = "app")]

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use damage_twin::app::commands::Command;
use damage_twin::app::settings::{CompareMode, Settings, TrainMode, TrainingSettings};
use damage_twin::app::state::{AppState, Photo, WorkerResult};
use damage_twin::scene::{Camera, Dataset, DatasetFormat, Intrinsics, Split, View};
use damage_twin::splats::Splats;
use damage_twin::train::history::{History, Sample};
use glam::{Quat, Vec3};

/// Polls until `done` holds (worker threads report asynchronously), at most 10 s.
fn poll_until(state: &mut AppState, done: impl Fn(&AppState) -> bool) {
    let start = Instant::now();
    while !done(state) {
        state.poll();
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "timed out; log: {:?}",
            state.log
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn tiny_splats() -> Splats {
    let mut s = Splats::empty(0, 0);
    for i in 0..4 {
        s.means.push(Vec3::new(i as f32 * 0.1, 0.0, 0.0));
        s.log_scales.push(Vec3::splat(-2.0));
        s.rotations.push(Quat::IDENTITY);
        s.raw_opacities.push(0.5);
        s.sh.extend_from_slice(&[0.1, 0.2, 0.3]);
        s.meta.push(i, 0);
    }
    s.check_lengths().expect("consistent test model");
    s
}

fn dataset_with_views(root: &std::path::Path, n: usize) -> Dataset {
    let k = Intrinsics {
        width: 64,
        height: 48,
        fx: 60.0,
        fy: 60.0,
        cx: 32.0,
        cy: 24.0,
    };
    let views = (0..n)
        .map(|i| {
            let a = i as f32 / n as f32 * std::f32::consts::TAU;
            View {
                name: format!("view{i:02}"),
                image_path: root.join(format!("missing{i}.png")),
                camera: Camera::look_at(
                    k,
                    Vec3::new(4.0 * a.cos(), 4.0 * a.sin(), 1.5),
                    Vec3::ZERO,
                    Vec3::Z,
                ),
                distortion: None,
                split: Split::Unspecified,
                ignore_mask: None,
            }
        })
        .collect();
    Dataset {
        root: root.to_path_buf(),
        format: DatasetFormat::ColmapText,
        views,
        image_files: n,
        camera_count: 1,
        camera_models: BTreeMap::new(),
        points: None,
        masks: None,
        mask_counts: BTreeMap::new(),
        background: [0.0; 3],
        warnings: Vec::new(),
        view_cache: None,
    }
}

fn open_dataset(state: &mut AppState, dataset: Dataset) {
    let source = dataset.root.clone();
    state
        .results_sender()
        .send(WorkerResult::Opened {
            source,
            dataset: Some(Arc::new(dataset)),
            splats: None,
            project_dir: None,
        })
        .expect("channel open");
    state.poll();
}

#[test]
fn settings_survive_a_storage_round_trip() {
    let mut s = Settings {
        background: [0.2, 0.3, 0.4],
        compare_mode: CompareMode::Blend,
        ..Settings::default()
    };
    s.training.mode = TrainMode::Overlay;
    s.damage.colours[0] = [0, 0, 255];
    s.remember(std::path::Path::new("/data/bridge"));
    let text = s.to_ron().expect("serialises");
    assert_eq!(Settings::from_ron(&text).expect("parses"), s);
}

#[test]
fn settings_from_before_versions_take_the_new_label_weight_default() {
    // What a viewer of 24 Nov stored: no version, the old default label weight.
    let old =
        "(training: (iterations: 3000, resolution_factor: 4, mode: label, label_weight: 0.1))";
    let s = Settings::from_ron(old).expect("parses");
    assert_eq!(s.training.scale, damage_twin::scene::ImageScale::Factor(4));
    assert_eq!(
        s.training.label_weight,
        TrainingSettings::default().label_weight
    );
    assert_eq!(s.version, Settings::default().version);
    let chosen = "(training: (label_weight: 0.5))";
    assert_eq!(
        Settings::from_ron(chosen)
            .expect("parses")
            .training
            .label_weight,
        0.5
    );
    // Once stored at the current version, 0.1 is the user's choice and stays.
    let mut current = Settings::default();
    current.training.label_weight = 0.1;
    let text = current.to_ron().expect("serialises");
    assert_eq!(
        Settings::from_ron(&text)
            .expect("parses")
            .training
            .label_weight,
        0.1
    );
}

#[test]
fn partial_or_bad_settings_fall_back_to_defaults() {
    let partial = Settings::from_ron("(fov_deg: 70.0, splat_scale: 1e9)").expect("parses");
    assert_eq!(partial.fov_deg, 70.0);
    assert_eq!(partial.splat_scale, 4.0, "clamped");
    assert_eq!(partial.training, Settings::default().training);
    assert!(Settings::from_ron("not ron at all").is_err());
}

#[test]
fn update_settings_command_applies_sanitised_values_to_the_camera() {
    let mut state = AppState::new(Settings::default());
    let mut s = state.settings.clone();
    s.fov_deg = f32::NAN;
    s.nav_mode = damage_twin::app::camera_controller::NavMode::Fly;
    state.apply(Command::UpdateSettings(Box::new(s)));
    assert_eq!(state.settings.fov_deg, Settings::default().fov_deg);
    assert_eq!(
        state.camera.mode,
        damage_twin::app::camera_controller::NavMode::Fly
    );
    assert!((state.camera.fov_y - 50f32.to_radians()).abs() < 1e-6);
}

#[test]
fn snapping_looks_through_the_survey_camera_and_unsnapping_continues_from_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut state = AppState::new(Settings::default());
    state.apply(Command::SnapToView(0));
    assert!(state.snap.is_none(), "nothing open: no-op");

    open_dataset(&mut state, dataset_with_views(dir.path(), 6));
    let survey = state.survey_cameras()[2];
    state.apply(Command::SnapToView(2));
    let view = state.view_camera(32, 24);
    assert_eq!(view.rotation, survey.rotation);
    assert_eq!(view.intrinsics.width, 32);
    // The photo does not exist: the worker reports a failure, the UI never waited for it.
    poll_until(&mut state, |s| {
        matches!(s.snap.as_ref().map(|s| &s.photo), Some(Photo::Failed(_)))
    });
    state.apply(Command::Unsnap);
    assert!(state.snap.is_none());
    assert!((state.camera.eye() - survey.position()).length() < 1e-3);
    state.apply(Command::SnapToView(99));
    assert!(state.snap.is_none());
    assert!(state.log.iter().any(|l| l.contains("no survey view 99")));
}

#[test]
fn opening_a_missing_path_reports_an_error() {
    let mut state = AppState::new(Settings::default());
    state.apply(Command::Open("/definitely/not/here".into()));
    poll_until(&mut state, |s| s.log.iter().any(|l| l.starts_with("error")));
    assert!(state.scene.is_none());
}

#[test]
fn commands_without_a_model_say_so() {
    let mut state = AppState::new(Settings::default());
    state.apply(Command::ExportPly("/tmp/never.ply".into()));
    state.apply(Command::SaveProject("/tmp/never".into()));
    state.apply(Command::StartTraining);
    assert!(state.training.is_none());
    assert_eq!(
        state
            .log
            .iter()
            .filter(|l| l.contains("nothing") || l.contains("open a dataset"))
            .count(),
        3,
        "{:?}",
        state.log
    );
}

#[test]
fn a_saved_twin_opens_again_with_the_same_model() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut state = AppState::new(Settings::default());
    state.set_splats(Arc::new(tiny_splats()));
    let project = dir.path().join("twin");
    state.apply(Command::SaveProject(project.clone()));
    assert!(project.join("twin.ron").is_file(), "{:?}", state.log);
    // Saved through the timeline: one survey (a bare model has no dataset), its model in its
    // own folder; saving again keeps the one survey rather than failing on a duplicate name.
    state.apply(Command::SaveProject(project.clone()));
    let twin = damage_twin::timeline::Twin::open(&project).expect("twin.ron reads back");
    assert_eq!(twin.project.surveys.len(), 1, "{:?}", state.log);
    let model = twin
        .model_path(&twin.project.surveys[0].name)
        .expect("survey")
        .expect("a model path");
    assert!(model.is_file(), "{}", model.display());
    assert!(model.starts_with(&project));
    let survey_dir = model.parent().expect("a folder").to_path_buf();
    let leftovers: Vec<_> = [&project, &survey_dir]
        .iter()
        .flat_map(|dir| std::fs::read_dir(dir).expect("readable"))
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("tmp"))
        .collect();
    assert!(
        leftovers.is_empty(),
        "atomic saves leave no temporary files"
    );

    let mut reopened = AppState::new(Settings::default());
    reopened.apply(Command::Open(project.clone()));
    poll_until(&mut reopened, |s| {
        s.splats.is_some() || s.log.iter().any(|l| l.starts_with("error"))
    });
    let splats = reopened
        .splats
        .as_ref()
        .unwrap_or_else(|| panic!("{:?}", reopened.log));
    assert_eq!(splats.len(), 4);
    assert_eq!(
        reopened.scene.as_ref().and_then(|s| s.project_dir.clone()),
        Some(project)
    );
}

#[test]
fn exported_png_has_the_viewport_size() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut state = AppState::new(Settings::default());
    state.set_splats(Arc::new(tiny_splats()));
    state.viewport_pixels = [80, 60];
    let path = dir.path().join("view.png");
    state.apply(Command::ExportPng(path.clone()));
    poll_until(&mut state, |s| {
        s.log
            .iter()
            .any(|l| l.starts_with("exported") || l.starts_with("error"))
    });
    let image = image::open(&path).unwrap_or_else(|e| panic!("{e}; log {:?}", state.log));
    assert_eq!((image.width(), image.height()), (80, 60));
}

#[test]
fn history_stays_bounded_and_keeps_its_ends() {
    let mut h = History::default();
    for i in 0..10_000u32 {
        h.push(Sample {
            wall_s: f64::from(i) * 0.01,
            step: i,
            loss: 1.0 / f64::from(i + 1),
            psnr: f64::NAN,
            gaussians: i as usize,
        });
    }
    assert!(h.samples.len() <= History::CAPACITY);
    assert_eq!(
        h.samples.first().map(|s| s.step),
        Some(0),
        "the first sample is always kept"
    );
    assert_eq!(h.last().map(|s| s.step), Some(9999));
    let rate = h.iterations_per_second().expect("a rate");
    assert!((rate - 100.0).abs() < 1.0, "{rate}");
}
