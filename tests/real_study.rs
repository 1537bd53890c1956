//! `damage-twin study real` (issue 42 §2–§3) on the stamp tests' small posed capture: a
//! segmenter that hands in the truth scores 1 on every photo and leaves the twin nothing to
//! correct; one that misses a photo's cracks scores 0 recall there and adds nothing; every
//! stage (twin, fine-tune, change detection, quantities) reports; the JSON reads back and the
//! chart is drawn; masks missing for a photo are refused in one line before any training.

#[allow(dead_code)] // `tree` is the stamp tests' own.
mod stamp_support;

use std::path::Path;

use damage_twin::scene::DamageClass;
use damage_twin::studies::real::chart::write_real_chart;
use damage_twin::studies::real::{RealStudy, RealStudyConfig, Segmenter, run_real};
use damage_twin::synth::stamp::stamp;
use stamp_support::{fixture, params};

/// The stamped survey 1's truth crack masks copied as a segmenter's output; `emptied` photos
/// get an empty mask.
fn segmenter_masks(stamped: &Path, out: &Path, emptied: &[&str]) {
    let from = stamped.join("survey-1/truth/masks/crack");
    let to = out.join("masks/crack");
    std::fs::create_dir_all(&to).unwrap();
    for entry in std::fs::read_dir(&from).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_owned();
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        if emptied.contains(&stem.as_str()) {
            let mask = image::open(&path).unwrap().to_luma8();
            image::GrayImage::new(mask.width(), mask.height())
                .save(to.join(&name))
                .unwrap();
        } else {
            std::fs::copy(&path, to.join(&name)).unwrap();
        }
    }
}

fn small() -> RealStudyConfig {
    RealStudyConfig {
        scale: 2,
        iterations: 300,
        fine_iterations: 20,
        threshold: 0.5,
    }
}

#[test]
fn the_study_scores_a_segmenter_against_the_stamped_truth_and_runs_every_stage() {
    let f = fixture();
    let stamped = f.root.join("stamped");
    stamp(&params(&f, "stamped", 3), &|_, _| {}).unwrap();
    let truth_views = std::fs::read_dir(stamped.join("survey-1/truth/masks/crack"))
        .unwrap()
        .count();
    assert_eq!(truth_views, 4);

    // A segmenter that is the truth but for photo 01, where it marks nothing.
    let seg = f.root.join("seg");
    segmenter_masks(&stamped, &seg, &["01"]);
    let mut lines = Vec::new();
    let study = run_real(
        &stamped,
        Segmenter::Masks(&seg),
        "truth but 01",
        &small(),
        Some(1),
        &mut |line| lines.push(line),
    )
    .unwrap();

    assert_eq!(study.views, 4);
    assert_eq!(study.segmenter_views.len(), 4);
    let mut with_cracks = 0;
    for row in &study.segmenter_views {
        if row.view == "01" {
            assert_eq!(row.marked_pixels, 0, "{row:?}");
            if row.truth_pixels > 0 {
                assert_eq!(row.recall, 0.0);
            }
        } else if row.truth_pixels > 0 {
            with_cracks += 1;
            assert_eq!(
                (row.iou, row.precision, row.recall),
                (1.0, 1.0, 1.0),
                "{row:?}"
            );
        }
    }
    assert!(with_cracks > 0, "no photo besides 01 shows a crack");
    assert_eq!(study.segmenter_pooled.precision, 1.0);
    // The segmenter added nothing: every wrong pixel it gave the twin is a missed one.
    assert_eq!(study.segmented_twin.correction.added, 0);
    assert_eq!(study.segmented_twin.model_train.precision, 1.0);

    // Every stage reported: the twins' classes, the fine-tune, survey 2's changes, quantities.
    let classes: Vec<_> = study
        .truth_twin
        .train
        .iter()
        .map(|c| c.class.as_str())
        .collect();
    assert!(classes.contains(&DamageClass::Crack.id()), "{classes:?}");
    assert!(
        study.refinement.is_some() != study.refinement_skipped.is_some(),
        "a fine-tune or the reason there is none: {lines:?}"
    );
    assert!(!study.change.is_empty(), "survey 2 adds damage: {lines:?}");
    assert!(study.change.iter().all(|c| c.truth_pixels > 0));
    let quantities: Vec<_> = study
        .quantities
        .iter()
        .map(|q| q.quantity.as_str())
        .collect();
    assert!(quantities.contains(&"crack length (m)"), "{quantities:?}");
    assert!(study.quantities.iter().all(|q| q.truth > 0.0));
    assert!(
        lines.iter().any(|l| l.contains("change detection")),
        "{lines:?}"
    );

    // The JSON reads back as written, and the chart is drawn from it.
    let json = serde_json::to_string(&study).unwrap();
    let back: RealStudy = serde_json::from_str(&json).unwrap();
    assert_eq!(back.segmenter_views, study.segmenter_views);
    let written = write_real_chart(&f.root, "real-study", &back).unwrap();
    for path in written {
        assert!(
            std::fs::metadata(&path).unwrap().len() > 1000,
            "{}",
            path.display()
        );
    }
}

#[test]
fn masks_missing_for_a_photo_are_refused_before_training() {
    let f = fixture();
    let stamped = f.root.join("stamped");
    stamp(&params(&f, "stamped", 3), &|_, _| {}).unwrap();
    let seg = f.root.join("seg");
    segmenter_masks(&stamped, &seg, &[]);
    std::fs::remove_file(seg.join("masks/crack/02.png")).unwrap();
    let started = std::time::Instant::now();
    let message = run_real(
        &stamped,
        Segmenter::Masks(&seg),
        "incomplete",
        &small(),
        Some(1),
        &mut |_| {},
    )
    .unwrap_err();
    assert!(
        message.contains("02.png") && message.contains("missing"),
        "{message}"
    );
    assert_eq!(message.lines().count(), 1, "{message}");
    assert!(
        started.elapsed().as_secs() < 30,
        "refused only after training"
    );
    // A folder that is not a stamped capture: one line naming it.
    let message = run_real(
        &f.capture,
        Segmenter::Masks(&seg),
        "x",
        &small(),
        Some(1),
        &mut |_| {},
    )
    .unwrap_err();
    assert_eq!(message.lines().count(), 1, "{message}");
    assert!(message.contains("survey-1"), "{message}");
}
