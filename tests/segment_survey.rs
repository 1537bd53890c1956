//! `twin add-survey --segment`: a survey that arrives as photos alone gets its masks from the
//! model, written into its dataset in the convention detection and the update read; a survey the
//! project would refuse is not segmented, and masks already there are never overwritten.

mod shared_data;

use std::path::Path;

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
    let params = damage_twin::synth::SynthParams {
        width: 192,
        height: 108,
        views: 4,
        views_survey2: 3,
        surveys: 2,
        sparse_points: 500,
        ..damage_twin::synth::SynthParams::demo(root.path().join("synth"))
    };
    damage_twin::synth::generate(&params, &|_, _| {}).unwrap();
    let second = root.path().join("synth/survey-2");
    // Photos alone: the synthetic masks are removed.
    std::fs::remove_dir_all(second.join("masks")).unwrap();
    let mut twin = Twin::create(&root.path().join("twin")).unwrap();
    twin.add_survey(
        "survey-1",
        "2026-03-01",
        &root.path().join("synth/survey-1"),
    )
    .unwrap();
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
