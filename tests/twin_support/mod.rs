//! Shared by the refinement and timeline tests: a tiny synthetic building (192×108, 12 views of
//! survey 1, and survey 2 when asked) and a coarse label-mode twin of survey 1 (half scale, 300
//! steps), small enough for `cargo test`.

use std::path::Path;
use std::sync::Arc;

use damage_twin::damage::setup::{RunConfig, prepare_run};
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::splats::Splats;
use damage_twin::train::job::JobOptions;
use damage_twin::train::run::train;

/// Generates the building into `dir/synth` (`surveys` 1 or 2; survey 2 with 8 views) and trains
/// the coarse twin of survey 1.
pub fn coarse_twin(dir: &Path, surveys: u32) -> (Arc<Dataset>, Splats) {
    let params = damage_twin::synth::SynthParams {
        width: 192,
        height: 108,
        views: 12,
        views_survey2: 8,
        surveys,
        sparse_points: 3000,
        ..damage_twin::synth::SynthParams::demo(dir.join("synth"))
    };
    damage_twin::synth::generate(&params, &|_, _| {}).expect("synth");
    let dataset = Arc::new(
        Dataset::open(&dir.join("synth/survey-1"), &OpenOptions::default()).expect("dataset"),
    );
    let config = RunConfig {
        scale: ImageScale::Factor(2),
        iterations: 300,
        ..RunConfig::default()
    };
    let run = prepare_run(&dataset, &config).expect("prepares");
    let outcome = train(run.setup, JobOptions::headless(None))
        .wait()
        .expect("trains");
    (dataset, (*outcome.splats).clone())
}
