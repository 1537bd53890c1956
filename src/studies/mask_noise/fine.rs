//! The mask-noise study's full-resolution stage: at the coarse resolution a one-pixel crack is
//! below the pixel grid, so the coarse twin's crack figures say more about the grid than about
//! the errors. Here the label-mode coarse twin is refined as the hierarchical method refines it
//! (select its damage Gaussians, hulls, fine-tune inside them at the photos' resolution) on the
//! photos' masks corrupted the same way at that resolution, and scored there against the clean
//! masks: errors corrected and introduced on the training views, IoU on training and held-out
//! views.

use std::sync::Arc;
use std::time::Instant;

use crate::damage::DamageClass;
use crate::damage::TrainMode;
use crate::damage::evaluate::{DamageReadout, evaluate_damage};
use crate::damage::reference::{ReferenceSource, load_reference_views};
use crate::damage::refine::{RefineConfig, Strategy, refine};
use crate::damage::select::SelectConfig;
use crate::scene::{Dataset, ImageScale, InMemoryMasks, Mask};
use crate::splats::Splats;
use crate::studies::mask_noise::clean::{corrupt, load_clean_training};
use crate::studies::mask_noise::rows::{StudyConfig, StudyRow, StudyStage};
use crate::studies::mask_noise::scores::{
    Inputs, agreement, heldout_psnr, rows_for, score_training_views,
};
use crate::train::job::{Job, JobOptions};

/// The resolution the stage refines and scores at: the photos'.
const FINE_SCALE: ImageScale = ImageScale::Factor(1);

/// The label-mode coarse twin `coarse`, trained on masks corrupted at `rate`, refined at full
/// resolution for `config.fine_iterations` steps and scored. The refinement reads the corrupted
/// full-resolution masks from memory (`scene::InMemoryMasks`).
/// `clean_twin`: the fine-tuned clean-mask twin's masks on the training views, for the rows'
/// `clean_twin_corrected`. Returns the rows and this twin's masks on the training views.
pub(crate) fn fine_rows(
    dataset: &Dataset,
    source: &ReferenceSource,
    config: &StudyConfig,
    rate: f32,
    coarse: &Splats,
    (train_indices, heldout_indices): (&[usize], &[usize]),
    clean_twin: Option<&[Vec<Mask>]>,
) -> Result<(Vec<StudyRow>, Vec<Vec<Mask>>), String> {
    let started = Instant::now();
    let mut fine_config = config.clone();
    fine_config.run.scale = FINE_SCALE;
    let clean = load_clean_training(dataset, source, train_indices, &fine_config)?;
    let heldout = load_reference_views(dataset, source, heldout_indices, FINE_SCALE)
        .map_err(|e| e.to_string())?;
    // Another draw of the same noise model: the photos' masks, not the coarse ones upsampled.
    let (noisy, corrupted) = corrupt(&clean, config.noise, rate, config.noise_seed ^ 0xF1E);

    // The refinement reads these masks where it reads a dataset's own: selection and the
    // fine-tune's label targets.
    let mut masks = InMemoryMasks::default();
    for (view, corrupted) in clean.views.iter().zip(&corrupted) {
        for (&class, mask) in DamageClass::ALL.iter().zip(corrupted) {
            masks.insert_damage(&view.name, class, mask.clone());
        }
    }
    // Held-out views keep their clean masks: the refinement scores itself on them.
    for view in &heldout {
        for (&class, mask) in DamageClass::ALL.iter().zip(&view.reference) {
            if let Some(mask) = mask {
                masks.insert_damage(&view.name, class, mask.clone());
            }
        }
    }
    let mut fine_dataset = dataset.clone();
    fine_dataset.masks = Some(Arc::new(masks));

    let refine_config = RefineConfig {
        select: SelectConfig {
            mode: TrainMode::Label,
            ..SelectConfig::default()
        },
        strategy: Strategy::Finetune,
        scale: FINE_SCALE,
        select_scale: config.run.scale,
        iterations: config.fine_iterations,
        holdout: config.run.holdout.clone(),
        background: config.run.background,
        seed: config.run.seed,
        label_weight: config.run.label_weight,
        label_geometry_until: config.fine_label_geometry_until,
        label_pos_weight: config.fine_label_pos_weight,
        ..RefineConfig::default()
    };
    let dataset_arc = Arc::new(fine_dataset);
    let model = coarse.clone();
    let job = Job::spawn("refine", JobOptions::headless(config.threads), move |ctx| {
        refine(ctx, &dataset_arc, &model, &refine_config)
    });
    let outcome = job
        .wait()
        .map_err(|e| format!("full-resolution fine-tune at rate {rate}: {e}"))?;
    let refined = &outcome.splats;

    let readout = DamageReadout {
        mode: TrainMode::Label,
        ..DamageReadout::for_model(refined, config.run.palette)
    };
    let training = score_training_views(
        refined,
        &clean,
        &corrupted,
        &noisy,
        &readout,
        config.run.background,
        clean_twin,
    );
    let heldout_scores = evaluate_damage(refined, &heldout, &readout, config.run.background);
    let input = agreement(&corrupted, &clean.reference, None);
    let input_noisy = agreement(&corrupted, &clean.reference, Some(&noisy));
    let mut fine_run = fine_config.run.clone();
    fine_run.mode = TrainMode::Label;
    let psnr = heldout_psnr(dataset, heldout_indices, &fine_run, refined);
    let inputs = Inputs {
        all: &input,
        noisy: &input_noisy,
        noisy_views: noisy.iter().filter(|&&n| n).count(),
    };
    let mut rows = rows_for(
        TrainMode::Label,
        rate,
        &inputs,
        &training,
        &heldout_scores,
        started.elapsed().as_secs_f64(),
        refined.len(),
        psnr,
    );
    for row in &mut rows {
        row.stage = StudyStage::Finetune;
    }
    Ok((rows, training.predicted))
}
