//! The mask-noise study: how much segmentation error the twin removes. At each corruption rate
//! the training masks get irregular regions added and cut out: by default in every view, with an
//! error of `rate ×` that view's damage area per class (the published method's Figure 11, so
//! every view contradicts the others somewhere: `NoiseModel::Area`); or, as `synth --mask-noise`
//! does, in a fraction `rate` of the views (`NoiseModel::Views`). The twin is trained on them in
//! each mode and its rendered masks are compared with the clean ones: of the pixels the
//! corruption got wrong, the share it puts right (errors corrected); of those it left right, the
//! share the twin gets wrong (errors introduced); and IoU on the training views (does multi-view
//! consistency outvote the errors?) and on held-out views (does the twin generalise?). Each
//! label-mode twin may also be refined at the photos' resolution and scored there
//! (`fine`), where a one-pixel crack is above the pixel grid.

use std::time::Instant;

use crate::damage::evaluate::{DamageReadout, evaluate_damage};
use crate::damage::reference::{load_reference_views, reference_source};
use crate::damage::setup::{RunConfig, model_and_spec, overlay_colours, prepare_targets};
use crate::damage::{Palette, TrainMode};
use crate::scene::{Dataset, Mask};
use crate::studies::mask_noise::clean::{corrupt, load_clean_training};
use crate::studies::mask_noise::fine::fine_rows;
use crate::studies::mask_noise::rows::{StudyConfig, StudyEvent, StudyRow, StudyStage};
use crate::studies::mask_noise::scores::{
    Inputs, agreement, heldout_psnr, rows_for, score_training_views,
};
use crate::train::job::{JobEvent, JobOptions};
use crate::train::run::{TrainSetup, train};
use crate::train::views::split_views;

/// Runs the study on `dataset` (which must have masks; a synthetic survey's `truth/` is used as
/// the clean reference when present).
pub fn run_study(
    dataset: &Dataset,
    config: &StudyConfig,
    on_event: &mut dyn FnMut(StudyEvent),
) -> Result<Vec<StudyRow>, String> {
    let source = reference_source(dataset).ok_or_else(|| {
        format!(
            "{} has no damage masks (masks/ or truth/masks/) to corrupt",
            dataset.root.display()
        )
    })?;
    let (train_indices, heldout_indices) = split_views(dataset, &config.run.holdout)?;
    let clean = load_clean_training(dataset, &source, &train_indices, config)?;
    let heldout = load_reference_views(dataset, &source, &heldout_indices, config.run.scale)
        .map_err(|e| e.to_string())?;

    let runs = config.rates.len() * config.modes.len();
    let mut rows = Vec::new();
    let mut run = 0;
    // Rate 0 first: its twins' masks are what the other rates' clean-twin figures read.
    let mut rates = config.rates.clone();
    rates.sort_by(f32::total_cmp);
    let mut clean_twins: Vec<(TrainMode, StudyStage, Vec<Vec<Mask>>)> = Vec::new();
    for rate in rates {
        let (noisy, corrupted) = corrupt(&clean, config.noise, rate, config.noise_seed);
        let input = agreement(&corrupted, &clean.reference, None);
        let input_noisy = agreement(&corrupted, &clean.reference, Some(&noisy));
        for &mode in &config.modes {
            on_event(StudyEvent::RunStarted {
                run,
                runs,
                mode,
                rate,
            });
            let started = Instant::now();
            let mut views = clean.views.clone();
            for (view, masks) in views.iter_mut().zip(&corrupted) {
                view.labels = masks.clone();
            }
            let run_config = RunConfig {
                mode,
                ..config.run.clone()
            };
            let overlay = overlay_colours(&views, &run_config, mode);
            let palette = overlay
                .as_ref()
                .map_or(config.run.palette, Palette::from_overlay);
            let (mut splats, spec) =
                model_and_spec(dataset, &views, &run_config, mode).map_err(|e| e.to_string())?;
            prepare_targets(&mut views, &mut splats, mode, overlay, &palette);
            let job = train(
                TrainSetup {
                    spec,
                    splats,
                    views,
                    heldout: Vec::new(),
                },
                JobOptions::headless(config.threads),
            );
            let outcome = job
                .wait_with(|event| {
                    if let JobEvent::Progress(p) = event
                        && (p.step % 50 == 0 || p.step == p.total)
                    {
                        on_event(StudyEvent::Step {
                            run,
                            step: p.step,
                            total: p.total,
                        })
                    }
                })
                .map_err(|e| format!("{mode} mode at rate {rate}: {e}"))?;
            let readout = DamageReadout {
                mode,
                ..DamageReadout::for_model(&outcome.splats, config.run.palette)
            };
            let training = score_training_views(
                &outcome.splats,
                &clean,
                &corrupted,
                &noisy,
                &readout,
                config.run.background,
                clean_twin(&clean_twins, mode, StudyStage::Coarse),
            );
            let heldout_scores =
                evaluate_damage(&outcome.splats, &heldout, &readout, config.run.background);
            let psnr = heldout_psnr(dataset, &heldout_indices, &run_config, &outcome.splats);
            let inputs = Inputs {
                all: &input,
                noisy: &input_noisy,
                noisy_views: noisy.iter().filter(|&&n| n).count(),
            };
            let run_rows = rows_for(
                mode,
                rate,
                &inputs,
                &training,
                &heldout_scores,
                started.elapsed().as_secs_f64(),
                outcome.splats.len(),
                psnr,
            );
            on_event(StudyEvent::RunFinished {
                run,
                rows: run_rows.clone(),
            });
            rows.extend(run_rows);
            if rate == 0.0 {
                clean_twins.push((mode, StudyStage::Coarse, training.predicted));
            }
            if mode == TrainMode::Label && config.fine_iterations > 0 {
                on_event(StudyEvent::FineStarted { rate });
                // A twin that shows no damage to refine is a finding of its own, not the end of
                // the study.
                match fine_rows(
                    dataset,
                    &source,
                    config,
                    rate,
                    &outcome.splats,
                    (&train_indices, &heldout_indices),
                    clean_twin(&clean_twins, mode, StudyStage::Finetune),
                ) {
                    Ok((fine, predicted)) => {
                        if rate == 0.0 {
                            clean_twins.push((mode, StudyStage::Finetune, predicted));
                        }
                        on_event(StudyEvent::RunFinished {
                            run,
                            rows: fine.clone(),
                        });
                        rows.extend(fine);
                    }
                    Err(error) => on_event(StudyEvent::FineFailed { rate, error }),
                }
            }
            run += 1;
        }
    }
    Ok(rows)
}

/// The masks of the twin trained on clean masks in `mode` at `stage`, once the study has it.
fn clean_twin(
    twins: &[(TrainMode, StudyStage, Vec<Vec<Mask>>)],
    mode: TrainMode,
    stage: StudyStage,
) -> Option<&[Vec<Mask>]> {
    twins
        .iter()
        .find(|(m, s, _)| *m == mode && *s == stage)
        .map(|(_, _, masks)| masks.as_slice())
}
