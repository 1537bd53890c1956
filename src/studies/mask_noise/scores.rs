//! The mask-noise study's scoring: the corrupted inputs and the twin against the clean masks on
//! the training views (errors corrected, by kind, and introduced; what the clean-mask twin makes
//! of the same pixels) and the rows they become.

use crate::damage::DamageClass;
use crate::damage::Palette;
use crate::damage::TrainMode;
use crate::damage::evaluate::{DamageReadout, DamageScores, ReferenceView, predicted_masks};
use crate::damage::setup::{RunConfig, apply_mode};
use crate::metrics::MaskAgreement;
use crate::raster::{Rasterizer, RenderOutput, RenderSettings};
use crate::scene::{Dataset, Mask};
use crate::studies::mask_noise::clean::CleanTraining;
use crate::studies::mask_noise::rows::{StudyRow, StudyStage};
use crate::train::views::load_views;

/// Agreement of the corrupted training masks with the clean ones, per class, over every
/// training view or (with `only`) over the flagged ones.
pub(crate) fn agreement(
    corrupted: &[Vec<Mask>],
    clean: &[ReferenceView],
    only: Option<&[bool]>,
) -> DamageScores {
    let mut scores = DamageScores::default();
    for (i, (masks, reference)) in corrupted.iter().zip(clean).enumerate() {
        if only.is_none_or(|flags| flags[i]) {
            scores.add_view(masks, &reference.reference);
        }
    }
    scores
}

/// The twin on the training views: against the clean masks on every view and on the corrupted
/// views only, and per class how many of the corrupted pixels (input ≠ clean) it renders right.
pub(crate) struct TrainingScores {
    all: DamageScores,
    noisy: DamageScores,
    /// Per class in `DamageClass::ALL` order: (pixels the input has right that the twin renders
    /// wrong, pixels the input has right).
    introduced: [(u64, u64); 3],
    /// Per class: (cut-out damage pixels the twin renders as damage, cut-out damage pixels).
    /// With `added`, the corrupted pixels (input ≠ clean) and those the twin renders right.
    missed: [(u64, u64); 3],
    /// Per class: (added pixels the twin renders as no damage, added pixels).
    added: [(u64, u64); 3],
    /// Per class: (corrupted pixels the clean-mask twin renders as the clean mask has them,
    /// corrupted pixels), when its masks were given.
    clean_twin: [(u64, u64); 3],
    /// The twin's masks per training view (`DamageClass::ALL` order): at rate 0, the clean twin's.
    pub(crate) predicted: Vec<Vec<Mask>>,
}

pub(crate) fn score_training_views(
    splats: &crate::splats::Splats,
    clean: &CleanTraining,
    corrupted: &[Vec<Mask>],
    noisy: &[bool],
    readout: &DamageReadout,
    background: glam::Vec3,
    clean_twin: Option<&[Vec<Mask>]>,
) -> TrainingScores {
    let settings = RenderSettings::new(background, splats.sh_degree);
    let (splats, readout) = readout.prepare(splats);
    let readout = &readout;
    let mut rasterizer = Rasterizer::new();
    let mut out = RenderOutput::default();
    let mut scores = TrainingScores {
        all: DamageScores::default(),
        noisy: DamageScores::default(),
        introduced: [(0, 0); 3],
        missed: [(0, 0); 3],
        added: [(0, 0); 3],
        clean_twin: [(0, 0); 3],
        predicted: Vec::with_capacity(clean.reference.len()),
    };
    for (i, view) in clean.reference.iter().enumerate() {
        rasterizer.forward(&splats, &view.camera, &settings, &mut out);
        let predicted = predicted_masks(&out, readout);
        scores.all.add_view(&predicted, &view.reference);
        if noisy[i] {
            scores.noisy.add_view(&predicted, &view.reference);
        }
        for (k, reference) in view.reference.iter().enumerate() {
            let Some(reference) = reference else { continue };
            let input = &corrupted[i][k].data;
            let clean_twin = clean_twin
                .and_then(|c| c.get(i))
                .and_then(|m| m.get(k))
                .map(|m| &m.data[..]);
            let pixels = reference.data.iter().zip(input).zip(&predicted[k].data);
            for (px, ((&r, &c), &p)) in pixels.enumerate() {
                let damage = r != 0;
                let twin_right = (p != 0) == damage;
                if damage != (c != 0) {
                    let kind = if damage {
                        &mut scores.missed[k]
                    } else {
                        &mut scores.added[k]
                    };
                    kind.1 += 1;
                    kind.0 += u64::from(twin_right);
                    if let Some(&t) = clean_twin.and_then(|m| m.get(px)) {
                        let counts = &mut scores.clean_twin[k];
                        counts.1 += 1;
                        counts.0 += u64::from((t != 0) == damage);
                    }
                } else {
                    let counts = &mut scores.introduced[k];
                    counts.1 += 1;
                    counts.0 += u64::from(!twin_right);
                }
            }
        }
        scores.predicted.push(predicted);
    }
    scores
}

/// The corrupted inputs' agreement with the clean masks.
pub(crate) struct Inputs<'a> {
    pub(crate) all: &'a DamageScores,
    pub(crate) noisy: &'a DamageScores,
    pub(crate) noisy_views: usize,
}

pub(crate) fn heldout_psnr(
    dataset: &Dataset,
    indices: &[usize],
    config: &RunConfig,
    splats: &crate::splats::Splats,
) -> Option<f64> {
    let mut views = load_views(dataset, indices, config.scale, true).ok()?;
    // Overlay targets in the colours the model was painted in.
    let palette = splats
        .overlay
        .as_ref()
        .map_or(config.palette, Palette::from_overlay);
    apply_mode(&mut views, config.mode, &palette);
    crate::train::evaluate::evaluate_views(splats, &views, config.background, splats.sh_degree)
        .map(|s| s.psnr)
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn rows_for(
    mode: TrainMode,
    rate: f32,
    input: &Inputs,
    train: &TrainingScores,
    heldout: &DamageScores,
    train_seconds: f64,
    gaussians: usize,
    heldout_psnr: Option<f64>,
) -> Vec<StudyRow> {
    let figure = |scores: &DamageScores, class: DamageClass, f: fn(&MaskAgreement) -> f64| {
        scores.classes.get(&class).map_or(f64::NAN, f)
    };
    DamageClass::ALL
        .iter()
        .filter(|c| {
            // Only classes there is something to find in: an absent class scores a vacuous 1.
            input
                .all
                .classes
                .get(c)
                .is_some_and(|a| a.true_positive + a.false_negative > 0)
        })
        .map(|&class| {
            let (missed_fixed, missed) = train.missed[class.channel()];
            let (added_fixed, added) = train.added[class.channel()];
            let (fixed, wrong) = (missed_fixed + added_fixed, missed + added);
            let (broken, right) = train.introduced[class.channel()];
            let (clean_fixed, clean_wrong) = train.clean_twin[class.channel()];
            let share = |part: u64, whole: u64| {
                if whole > 0 {
                    part as f64 / whole as f64
                } else {
                    f64::NAN
                }
            };
            StudyRow {
                mode,
                stage: StudyStage::Coarse,
                rate,
                class,
                input_iou: figure(input.all, class, MaskAgreement::iou),
                twin_iou_train: figure(&train.all, class, MaskAgreement::iou),
                twin_iou_heldout: figure(heldout, class, MaskAgreement::iou),
                twin_f1_heldout: figure(heldout, class, MaskAgreement::f1),
                twin_precision_heldout: figure(heldout, class, MaskAgreement::precision),
                twin_recall_heldout: figure(heldout, class, MaskAgreement::recall),
                input_iou_noisy_views: figure(input.noisy, class, MaskAgreement::iou),
                twin_iou_noisy_views: figure(&train.noisy, class, MaskAgreement::iou),
                corrupted_pixels: wrong,
                errors_corrected: share(fixed, wrong),
                missed_corrected: share(missed_fixed, missed),
                added_corrected: share(added_fixed, added),
                clean_twin_corrected: share(clean_fixed, clean_wrong),
                errors_introduced: share(broken, right),
                noisy_views: input.noisy_views,
                train_seconds,
                gaussians,
                heldout_psnr,
            }
        })
        .collect()
}
