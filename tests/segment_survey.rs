//! `twin add-survey --segment`: a survey that arrives as photos alone gets its masks from the
//! model, written into its dataset in the convention detection and the update read; a survey the
//! project would refuse is not segmented, and masks already there are never overwritten. The
//! same through the built binary: `damage-twin twin add-survey --segment MODEL`.

mod shared_data;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use damage_twin::scene::masks::count_masks;
use damage_twin::scene::{DamageClass, ImageScale};
use damage_twin::segment::{
    PhotoSettings, Preprocess, SegmentError, SegmentModel, SegmentSettings, Tiling,
};
use damage_twin::timeline::segment_survey::NewSurvey;
use damage_twin::timeline::survey::AlignMode;
use damage_twin::timeline::{TimelineError, Twin};

fn settings() -> SegmentSettings {
    SegmentSettings {
        classes: vec![Some(DamageClass::Crack)],
        photo: PhotoSettings {
            preprocess: Preprocess::default(),
            scale: ImageScale::Factor(1),
            tiling: Tiling::default(),
        },
        threshold: 0.5,
        overwrite: false,
        background: [0.0; 3],
    }
}

/// A two-survey synthetic building (192×108; survey 2 with 3 photos and its masks removed:
/// photos alone) under `root/synth`, and a project `root/twin` holding survey 1 (saved). Returns
/// the project and survey 2's dataset.
fn project_of_photos(root: &Path) -> (Twin, PathBuf) {
    let params = damage_twin::synth::SynthParams {
        width: 192,
        height: 108,
        views: 4,
        views_survey2: 3,
        surveys: 2,
        sparse_points: 500,
        ..damage_twin::synth::SynthParams::demo(root.join("synth"))
    };
    damage_twin::synth::generate(&params, &|_, _| {}).unwrap();
    let second = root.join("synth/survey-2");
    std::fs::remove_dir_all(second.join("masks")).unwrap();
    let mut twin = Twin::create(&root.join("twin")).unwrap();
    twin.add_survey("survey-1", "2026-03-01", &root.join("synth/survey-1"))
        .unwrap();
    twin.save().unwrap();
    (twin, second)
}

fn survey<'a>(dataset: &'a Path, date: &'a str) -> NewSurvey<'a> {
    NewSurvey {
        name: "survey-2",
        date,
        dataset,
        align: AlignMode::SameFrame,
    }
}

#[test]
fn a_survey_of_photos_alone_is_segmented_into_its_dataset_before_it_is_added() {
    let Some(model_path) = shared_data::path("crack_unet_crackpot/crack_unet.onnx") else {
        return;
    };
    let model = SegmentModel::open(&model_path, 1).unwrap();
    let root = tempfile::tempdir().unwrap();
    let (mut twin, second) = project_of_photos(root.path());
    let before = twin.project.clone();

    // A date before the latest survey's is refused before any photo is segmented.
    let refused = twin.segment_new_survey(
        survey(&second, "2025-01-01"),
        &model,
        &settings(),
        &mut |_, _| true,
    );
    assert!(
        matches!(refused, Err(TimelineError::Survey { .. })),
        "{refused:?}"
    );
    assert!(!second.join("masks").exists());

    let mut reported = Vec::new();
    let summary = twin
        .segment_new_survey(
            survey(&second, "2026-09-01"),
            &model,
            &settings(),
            &mut |done, total| {
                reported.push((done, total));
                true
            },
        )
        .unwrap();
    assert_eq!(summary.photos, 3);
    assert_eq!(reported.last(), Some(&(3, 3)));
    assert_eq!(
        count_masks(&second.join("masks")).get(&DamageClass::Crack),
        Some(&3)
    );
    assert!(second.join("probabilities/crack").is_dir());
    // The project is unchanged until the survey is added, and then reads the masks.
    assert_eq!(twin.project, before);
    twin.add_placed_survey("survey-2", "2026-09-01", &second, AlignMode::SameFrame)
        .unwrap();
    let dataset = twin.open_survey_dataset("survey-2").unwrap();
    assert_eq!(dataset.mask_counts.get(&DamageClass::Crack), Some(&3));

    // Segmenting again would overwrite those masks: refused, naming one.
    let mut again = twin.clone();
    again.project = before;
    let err = again
        .segment_new_survey(
            survey(&second, "2026-09-01"),
            &model,
            &settings(),
            &mut |_, _| true,
        )
        .unwrap_err();
    assert!(
        matches!(err, TimelineError::Segment(SegmentError::Exists { .. })),
        "{err}"
    );
    assert!(err.to_string().contains("masks/crack/"), "{err}");
}

fn add_survey_cli(project: &Path, dataset: &Path, model: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_damage-twin"))
        .args(["twin", "add-survey"])
        .arg(project)
        .args(["--survey", "survey-2", "--date", "2026-09-01", "--dataset"])
        .arg(dataset)
        .arg("--segment")
        .arg(model)
        .args(["--threshold", "0.4", "--threads", "2", "--quiet"])
        .output()
        .expect("runs the binary")
}

#[test]
fn the_binary_segments_then_adds_and_refuses_to_segment_over_the_masks() {
    let Some(model) = shared_data::path("crack_unet_crackpot/crack_unet.onnx") else {
        return;
    };
    let root = tempfile::tempdir().unwrap();
    let (twin, second) = project_of_photos(root.path());
    let project = twin.dir().to_path_buf();

    let run = add_survey_cli(&project, &second, &model);
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stdout}{stderr}");
    assert!(
        stdout.contains("segmented 3 photos") && stdout.contains("on 2 threads"),
        "{stdout}"
    );
    assert!(
        stdout.contains("added survey survey-2 (same frame)"),
        "{stdout}"
    );
    assert_eq!(
        count_masks(&second.join("masks")).get(&DamageClass::Crack),
        Some(&3)
    );
    let added = Twin::open(&project).unwrap();
    assert_eq!(added.survey("survey-2").unwrap().date, "2026-09-01");
    let saved = std::fs::read(added.file()).unwrap();

    // The same again: the name is taken (refused before a photo is segmented); the masks stay.
    let masks = folder_files(&second.join("masks/crack"));
    assert_eq!(masks.len(), 3);
    let again = add_survey_cli(&project, &second, &model);
    let stderr = String::from_utf8_lossy(&again.stderr);
    assert_eq!(again.status.code(), Some(1), "{stderr}");
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(errors.len(), 1, "one error line: {stderr}");
    assert!(
        errors[0].contains("already exists") && errors[0].contains("twin.ron"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(added.file()).unwrap(), saved);
    assert_eq!(folder_files(&second.join("masks/crack")), masks);
}

/// The files of `folder` and their bytes, by name.
fn folder_files(folder: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut files: Vec<(PathBuf, Vec<u8>)> = std::fs::read_dir(folder)
        .unwrap()
        .map(|e| {
            let path = e.unwrap().path();
            let bytes = std::fs::read(&path).unwrap();
            (path, bytes)
        })
        .collect();
    files.sort();
    files
}
