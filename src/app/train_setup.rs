//! The viewer's training settings as a run (`damage::setup`): every-8th held-out rule, the
//! chosen mode, the damage layer's colours as the overlay palette. Runs on the training worker;
//! shared by the app and the headless demo.

use crossbeam_channel::Sender;

use crate::app::settings::TrainingSettings;
use crate::damage::Palette;
use crate::damage::setup::{RunConfig, prepare_run};
use crate::scene::{Dataset, ImageScale};
use crate::train::job::{JobEvent, TrainSetup};
use crate::train::views::Holdout;

/// Random initial points when the dataset has none (3DGS uses 100k for NeRF-synthetic; a few
/// thousand converge faster on a CPU and densification adds the rest).
const RANDOM_POINTS: usize = 5_000;

/// The run the viewer's settings describe.
pub fn run_config(
    settings: &TrainingSettings,
    palette: Palette,
    background: [f32; 3],
) -> RunConfig {
    RunConfig {
        mode: settings.mode,
        palette,
        scale: ImageScale::Factor(settings.resolution_factor.max(1)),
        iterations: settings.iterations.max(1),
        holdout: Holdout::Auto { every: 8 },
        background: glam::Vec3::from_array(background),
        label_weight: settings.label_weight,
        random_points: RANDOM_POINTS,
        // Ten held-out evaluations over the run for the PSNR chart.
        eval_every: (settings.iterations / 10).max(1),
        ..RunConfig::default()
    }
}

/// Everything the job needs, loaded and initialised; notes go to the job's log.
pub fn setup(
    dataset: &Dataset,
    config: &RunConfig,
    log_tx: Option<&Sender<JobEvent>>,
) -> Result<TrainSetup, String> {
    let run = prepare_run(dataset, config)?;
    if let Some(tx) = log_tx {
        for note in run.notes {
            let _ = tx.send(JobEvent::Log(note));
        }
    }
    Ok(run.setup)
}
