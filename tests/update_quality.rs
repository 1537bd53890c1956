//! What holds a survey update's quality, measured (docs/TIMELINE.md "What holds the update
//! back"): the refinement reports how much of the held-out true damage its hulls cover, a study's
//! oracle draws the hulls from the truth masks instead, a run stops when its hull loss stops
//! improving, and the update study gathers updates' metrics into rows. On the tiny building.

mod twin_support;

use std::sync::Arc;

use damage_twin::damage::refine::{RefineConfig, RefineOutcome, Strategy, refine_job};
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::splats::Splats;
use damage_twin::studies::update::{read_row, update_table};
use damage_twin::train::job::JobOptions;
use damage_twin::train::plateau::{Plateau, stop_step};

fn refined(dataset: &Arc<Dataset>, coarse: &Splats, config: RefineConfig) -> RefineOutcome {
    let config = RefineConfig {
        strategy: Strategy::Finetune,
        scale: ImageScale::Factor(1),
        select_scale: ImageScale::Factor(2),
        ..config
    };
    refine_job(
        dataset.clone(),
        Arc::new(coarse.clone()),
        config,
        JobOptions::headless(None),
    )
    .wait()
    .expect("refines")
}

#[test]
fn hull_coverage_is_reported_truth_hulls_cover_all_damage_and_a_flat_loss_stops_the_run() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (dataset, coarse) = twin_support::coarse_twin(dir.path(), 1);

    // Drawn hulls cover part of the held-out truth; the oracle's cover all of it.
    let drawn = refined(
        &dataset,
        &coarse,
        RefineConfig {
            iterations: 20,
            ..RefineConfig::default()
        },
    );
    let coverage = drawn.report.hull_coverage.clone().expect("truth masks");
    assert!(!coverage.is_empty());
    assert!(
        coverage.values().all(|&c| (0.0..=1.0).contains(&c)),
        "{coverage:?}"
    );
    assert_eq!(drawn.report.iterations, 20);
    let oracle = refined(
        &dataset,
        &coarse,
        RefineConfig {
            iterations: 20,
            hulls_from_truth: true,
            ..RefineConfig::default()
        },
    );
    let full = oracle.report.hull_coverage.clone().expect("truth masks");
    assert_eq!(
        full.keys().collect::<Vec<_>>(),
        coverage.keys().collect::<Vec<_>>()
    );
    assert!(full.values().all(|&c| c == 1.0), "{full:?}");

    // A gain no window reaches: the first window sets the best, the second is flat, the run
    // stops there instead of running its 60 steps.
    let stopped = refined(
        &dataset,
        &coarse,
        RefineConfig {
            iterations: 60,
            stop_when_flat: Some(Plateau {
                window: 5,
                min_gain: 0.9,
                patience: 1,
            }),
            ..RefineConfig::default()
        },
    );
    assert_eq!(stopped.report.iterations, 10);
}

const RULE: Plateau = Plateau {
    window: 10,
    min_gain: 0.01,
    patience: 2,
};

#[test]
fn a_falling_loss_runs_on_and_a_flat_one_stops_after_patience_windows() {
    // Falls 5 % a window for 60 steps, then flat: the windows ending at 70 and 80 are flat.
    let losses = (0..200).map(|s: i32| 0.95f32.powi((s / 10).min(5)));
    assert_eq!(stop_step(RULE, losses), Some(80));
    let falling = (0..200).map(|s: i32| 0.95f32.powi(s / 10));
    assert_eq!(stop_step(RULE, falling), None);
}

#[test]
fn one_noisy_window_does_not_stop_the_run_and_rolled_back_steps_are_skipped() {
    // The third window is worse (noise), the fourth improves again: the flat count resets.
    let mut losses: Vec<f32> = Vec::new();
    for mean in [1.0, 0.9, 0.95, 0.8, 0.7, 0.6] {
        losses.extend(std::iter::repeat_n(mean, 10));
    }
    losses.insert(5, f32::NAN);
    assert_eq!(stop_step(RULE, losses), None);
}

const METRICS: &str = r#"{"survey":"2025","seconds":50.0,"previous_look_psnr_before":25.0,
    "previous_look_psnr_after":24.5,"refine":{"iterations":300,"width":480,"height":270,
    "ms_per_refine_step":90.0,"hull_coverage":{"crack":0.8},
    "before":{"iou":{"crack":0.3}},"after":{"iou":{"crack":0.6}}}}"#;

#[test]
fn an_update_study_row_reads_an_updates_metrics_and_its_share_of_from_scratch() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("metrics.json");
    std::fs::write(&path, METRICS).expect("writes");
    let row = read_row("plateau", &path, Some(500.0)).expect("reads");
    assert_eq!(row.steps, 300);
    assert_eq!(row.iou_after["crack"], 0.6);
    assert_eq!(row.share_of_from_scratch, Some(0.1));
    let table = update_table(&[row]);
    assert!(
        table.contains(
            "| plateau | 480×270 | 300 | 50.0 | 10.0 % | 0.300 → 0.600 | 0.800 | 25.00 → 24.50 dB |"
        ),
        "{table}"
    );
    std::fs::write(&path, "{}").expect("writes");
    let err = read_row("x", &path, None).unwrap_err().to_string();
    assert!(err.contains("metrics.json: not an update's"), "{err}");
}
