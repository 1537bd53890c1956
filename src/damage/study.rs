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
//! (`study_fine`), where a one-pixel crack is above the pixel grid.

use std::time::Instant;

use serde::Serialize;

use crate::damage::evaluate::{DamageReadout, ReferenceView, evaluate_damage};
use crate::damage::reference::{ReferenceSource, load_reference_views, reference_source};
use crate::damage::setup::{RunConfig, model_and_spec, overlay_colours, prepare_targets};
use crate::damage::study_fine::fine_rows;
use crate::damage::study_scores::{
    Inputs, agreement, heldout_psnr, rows_for, score_training_views,
};
use crate::damage::{DamageClass, Palette, TrainMode};
use crate::scene::masks::resize_mask_nearest;
use crate::scene::{Dataset, Mask};
use crate::synth::corrupt::{corrupt_class_mask, corrupt_mask_by_area, noisy_views};
use crate::train::job::{JobEvent, JobOptions};
use crate::train::run::{TrainSetup, train};
use crate::train::spec::TrainView;
use crate::train::views::{load_views, split_views};

/// How the training masks are corrupted at a rate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NoiseModel {
    /// Every view, with an error of `rate ×` its damage area per class.
    #[default]
    Area,
    /// A fraction `rate` of the views, a few blobs each (`synth --mask-noise`).
    Views,
}

impl std::str::FromStr for NoiseModel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "area" => Ok(NoiseModel::Area),
            "views" => Ok(NoiseModel::Views),
            other => Err(format!("unknown noise model {other:?}: use area or views")),
        }
    }
}

/// Which twin a row scores: the coarse one trained on the corrupted masks, or that twin refined
/// at the photos' resolution on them (`study_fine`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StudyStage {
    #[default]
    Coarse,
    Finetune,
}

impl std::fmt::Display for StudyStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            StudyStage::Coarse => "coarse",
            StudyStage::Finetune => "finetune",
        })
    }
}

/// The study's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct StudyConfig {
    /// Error per view as a fraction of its damage area (`Area`), or the fraction of training
    /// views whose masks are corrupted (`Views`).
    pub rates: Vec<f32>,
    pub noise: NoiseModel,
    pub modes: Vec<TrainMode>,
    /// The run at every rate and mode (its `mode` is replaced by each of `modes`).
    pub run: RunConfig,
    /// Seed of the corruption (which views, which blobs).
    pub noise_seed: u64,
    pub threads: Option<usize>,
    /// Steps of the full-resolution fine-tune of each label-mode twin (0: none).
    pub fine_iterations: u32,
    /// The fraction of the fine-tune during which the label loss shapes the geometry (None: all
    /// of it; `Targets::label_geometry_steps`). Apart from the coarse run's
    /// (`run.label_geometry_until`): at full resolution the fine-tune's work is to reshape the
    /// damage's geometry to the masks.
    pub fine_label_geometry_until: Option<f32>,
    /// Weight of damage pixels in the fine-tune's label cross-entropy
    /// (`RefineConfig::label_pos_weight`).
    pub fine_label_pos_weight: f32,
    /// Where the fine-tune's corrupted full-resolution masks are written while it runs.
    pub fine_work_dir: std::path::PathBuf,
}

/// One (mode, rate, class) result.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct StudyRow {
    pub mode: TrainMode,
    /// Rows written before the fine-tune stage existed are coarse.
    #[serde(default)]
    pub stage: StudyStage,
    pub rate: f32,
    pub class: DamageClass,
    /// IoU of the corrupted training masks against the clean ones.
    #[serde(deserialize_with = "nan_if_null")]
    pub input_iou: f64,
    /// IoU of the twin's rendered masks against the clean ones, on the training views.
    #[serde(deserialize_with = "nan_if_null")]
    pub twin_iou_train: f64,
    /// The same on held-out views.
    #[serde(deserialize_with = "nan_if_null")]
    pub twin_iou_heldout: f64,
    pub twin_f1_heldout: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub twin_precision_heldout: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub twin_recall_heldout: f64,
    /// IoU of the corrupted masks against the clean ones on the corrupted views only.
    #[serde(deserialize_with = "nan_if_null")]
    pub input_iou_noisy_views: f64,
    /// IoU of the twin against the clean masks on the same (corrupted) views.
    #[serde(deserialize_with = "nan_if_null")]
    pub twin_iou_noisy_views: f64,
    /// Pixels of the training views where the corrupted mask disagrees with the clean one.
    pub corrupted_pixels: u64,
    /// Of those, the fraction the twin renders as the clean mask has them (errors corrected).
    #[serde(deserialize_with = "nan_if_null", alias = "corrupted_pixels_corrected")]
    pub errors_corrected: f64,
    /// Errors corrected split by kind: of the damage pixels the corruption cut out, the fraction
    /// the twin renders as damage...
    #[serde(deserialize_with = "nan_if_null", default = "nan")]
    pub missed_corrected: f64,
    /// ...and of the pixels it added, the fraction the twin renders as no damage.
    #[serde(deserialize_with = "nan_if_null", default = "nan")]
    pub added_corrected: f64,
    /// Of the same corrupted pixels, the fraction the twin trained on the clean masks (rate 0, same
    /// mode and stage) renders as the clean mask has them: the most a twin at this resolution
    /// can be expected to correct (NaN when the study has no rate 0).
    #[serde(deserialize_with = "nan_if_null", default = "nan")]
    pub clean_twin_corrected: f64,
    /// Of the training-view pixels where the corrupted mask is right, the fraction the twin
    /// renders wrong (errors introduced; at rate 0, the clean-mask twin's own error).
    #[serde(deserialize_with = "nan_if_null", default = "nan")]
    pub errors_introduced: f64,
    /// Views whose masks were corrupted, of the training views.
    pub noisy_views: usize,
    #[serde(deserialize_with = "nan_if_null")]
    pub train_seconds: f64,
    pub gaussians: usize,
    pub heldout_psnr: Option<f64>,
}

fn nan() -> f64 {
    f64::NAN
}

/// JSON has no NaN (serde_json writes null): read null back as NaN.
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    use serde::Deserialize;
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Progress of the study, for a progress bar.
#[derive(Clone, Debug)]
pub enum StudyEvent {
    RunStarted {
        run: usize,
        runs: usize,
        mode: TrainMode,
        rate: f32,
    },
    Step {
        run: usize,
        step: u32,
        total: u32,
    },
    RunFinished {
        run: usize,
        rows: Vec<StudyRow>,
    },
    /// The full-resolution fine-tune of the label-mode twin at `rate` began.
    FineStarted {
        rate: f32,
    },
    /// It could not run (no damage Gaussians to refine, say): no fine-tune rows at `rate`.
    FineFailed {
        rate: f32,
        error: String,
    },
}

/// Clean masks of the training views and what is needed to corrupt them.
pub(crate) struct CleanTraining {
    pub(crate) views: Vec<TrainView>,
    /// Per view, where added blobs may be centred (not sky), when the dataset says.
    building: Vec<Vec<bool>>,
    pub(crate) reference: Vec<ReferenceView>,
}

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

pub(crate) fn load_clean_training(
    dataset: &Dataset,
    source: &ReferenceSource,
    indices: &[usize],
    config: &StudyConfig,
) -> Result<CleanTraining, String> {
    let scale = config.run.scale;
    let mut views = load_views(dataset, indices, scale, false).map_err(|e| e.to_string())?;
    let reference =
        load_reference_views(dataset, source, indices, scale).map_err(|e| e.to_string())?;
    let mut building = Vec::with_capacity(views.len());
    for (view, reference) in views.iter_mut().zip(&reference) {
        let (w, h) = (view.image.width, view.image.height);
        view.labels = reference
            .reference
            .iter()
            .map(|m| m.clone().unwrap_or_else(|| Mask::empty(w, h)))
            .collect();
        building.push(structure_pixels(dataset, &view.name, w, h));
    }
    Ok(CleanTraining {
        views,
        building,
        reference,
    })
}

/// Pixels showing the structure (not sky), from a synthetic survey's component labels
/// (`truth/components/<view>.png`, sky = 0); every pixel when there are none.
fn structure_pixels(dataset: &Dataset, name: &str, width: u32, height: u32) -> Vec<bool> {
    let path = dataset
        .root
        .join("truth/components")
        .join(format!("{name}.png"));
    let all = || vec![true; width as usize * height as usize];
    let Ok(image) = image::open(&path) else {
        return all();
    };
    let grey = image.to_luma8();
    let ids = Mask {
        width: grey.width(),
        height: grey.height(),
        data: grey.into_raw(),
    };
    resize_mask_nearest(&ids, width, height)
        .data
        .iter()
        .map(|&id| id != 0)
        .collect()
}

/// The training masks at `rate`: which views are noisy, and per view per class the masks.
pub(crate) fn corrupt(
    clean: &CleanTraining,
    noise: NoiseModel,
    rate: f32,
    seed: u64,
) -> (Vec<bool>, Vec<Vec<Mask>>) {
    let noisy = match noise {
        NoiseModel::Area => vec![rate > 0.0; clean.views.len()],
        NoiseModel::Views => noisy_views(clean.views.len(), rate, seed),
    };
    let mut rng = fastrand::Rng::with_seed(seed ^ 0x5EED_0FB1_0B00);
    let masks = clean
        .views
        .iter()
        .zip(&noisy)
        .zip(&clean.building)
        .map(|((view, &is_noisy), building)| {
            let mut masks = view.labels.clone();
            if is_noisy {
                for (class, mask) in DamageClass::ALL.iter().zip(masks.iter_mut()) {
                    let (w, h) = (mask.width as usize, mask.height as usize);
                    match noise {
                        NoiseModel::Area => {
                            corrupt_mask_by_area(&mut mask.data, w, h, building, rate, &mut rng);
                        }
                        NoiseModel::Views => {
                            corrupt_class_mask(*class, &mut mask.data, w, h, building, &mut rng)
                        }
                    }
                }
            }
            masks
        })
        .collect();
    (noisy, masks)
}
