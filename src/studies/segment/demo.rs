//! The demo building through a real segmenter: survey 1 of the procedural building (small, as
//! configured) has its photos segmented by the model into a folder of their own (the synthetic
//! truth is never read to make them), a label-mode twin is trained on those masks, and both the
//! model's masks and the twin's rendered crack masks are scored against the clean truth
//! (`truth/masks/`) on the training views, and the twin also on held-out views. Does multi-view
//! fusion correct a real segmenter's errors, and by how much?

use std::path::Path;

use crate::damage::TrainMode;
use crate::damage::evaluate::{
    DamageReadout, DamageScores, ReferenceView, evaluate_damage, predicted_masks,
};
use crate::damage::reference::{load_reference_views, reference_source};
use crate::damage::setup::{RunConfig, prepare_run};
use crate::metrics::MaskAgreement;
use crate::raster::{Rasterizer, RenderOutput, RenderSettings};
use crate::scene::masks::count_masks;
use crate::scene::open::OpenOptions;
use crate::scene::{DamageClass, Dataset, ImageScale, MaskFolder};
use crate::segment::{
    PhotoSettings, Preprocess, SegmentModel, SegmentSettings, SegmentSummary, Tiling,
    dataset_photos, segment_photos,
};
use crate::studies::segment::crack_sets::write_overlay;
use crate::studies::segment::rows::{DemoResult, SegmentStudyConfig};
use crate::synth::{self, SynthParams};
use crate::train::job::JobOptions;
use crate::train::run::train;

/// Runs the demo part in `work` (the synthetic survey and the segmented masks are written
/// there); overlays of the first view (model, twin) go to `figures`.
pub fn run_demo(
    model: &SegmentModel,
    config: &SegmentStudyConfig,
    work: &Path,
    figures: &Path,
    threads: Option<usize>,
    on_line: &mut dyn FnMut(String),
) -> Result<DemoResult, String> {
    let params = SynthParams {
        width: config.demo_width,
        height: config.demo_height,
        views: config.demo_views,
        surveys: 1,
        sparse_points: 5_000,
        ..SynthParams::demo(work.join("demo"))
    };
    on_line(format!(
        "demo building: {} views at {}×{}",
        params.views, params.width, params.height
    ));
    let output = synth::generate(&params, &|_, _| {}).map_err(|e| e.to_string())?;
    let survey = output
        .surveys
        .first()
        .ok_or("the synthetic building has no survey")?;
    let mut dataset =
        Dataset::open(&survey.dir, &OpenOptions::default()).map_err(|e| e.to_string())?;

    // The photos through the model, into a folder of their own: the survey's own masks/ (the
    // synthetic truth) stay untouched and unused for training.
    let segmented = work.join("segmented");
    let summary = segment_cracks_into(model, &dataset, &segmented, config.threshold)?;
    on_line(format!(
        "segmented {} photos: {:.2} % of pixels marked crack",
        summary.photos,
        100.0 * summary.damage_fraction.get("crack").copied().unwrap_or(0.0)
    ));
    let reference = reference_source(&dataset).ok_or("the synthetic survey has no truth/")?;
    dataset.masks = Some(MaskFolder::shared(segmented.join("masks")));
    dataset.mask_counts = count_masks(&segmented.join("masks"));

    let run = RunConfig {
        mode: TrainMode::Label,
        iterations: config.demo_iterations,
        scale: ImageScale::Factor(1),
        ..RunConfig::default()
    };
    let prepared = prepare_run(&dataset, &run).map_err(|e| e.to_string())?;
    let (train_indices, heldout_indices) = (
        prepared.train_indices.clone(),
        prepared.heldout_indices.clone(),
    );
    let outcome = train(prepared.setup, JobOptions::headless(threads))
        .wait()
        .map_err(|e| e.to_string())?;
    on_line(format!(
        "label-mode twin: {} steps in {:.0} s, {} Gaussians",
        outcome.steps,
        outcome.seconds,
        outcome.splats.len()
    ));

    let truth_train = load_reference_views(&dataset, &reference, &train_indices, run.scale)
        .map_err(|e| e.to_string())?;
    let truth_heldout = load_reference_views(&dataset, &reference, &heldout_indices, run.scale)
        .map_err(|e| e.to_string())?;
    let segmented_source = MaskFolder::new(segmented.join("masks"));
    let model_scores =
        |indices: &[usize], truths: &[ReferenceView]| -> Result<(DamageScores, f64), String> {
            let mut scores = DamageScores::default();
            let mut per_view = 0.0;
            for (&index, truth) in indices.iter().zip(truths) {
                let (_, masks) = dataset
                    .load_view_masks(index, &segmented_source, run.scale)
                    .map_err(|e| e.to_string())?;
                let predicted: Vec<_> = DamageClass::ALL
                    .iter()
                    .map(|c| {
                        masks.get(c).cloned().unwrap_or_else(|| {
                            crate::scene::Mask::empty(
                                truth.camera.intrinsics.width,
                                truth.camera.intrinsics.height,
                            )
                        })
                    })
                    .collect();
                scores.add_view_where(&predicted, &truth.reference, truth.used.as_ref());
                let mut one = DamageScores::default();
                one.add_view_where(&predicted, &truth.reference, truth.used.as_ref());
                per_view += crack(&one, MaskAgreement::iou);
            }
            Ok((scores, per_view / indices.len().max(1) as f64))
        };
    let (model_train, model_per_view) = model_scores(&train_indices, &truth_train)?;
    let (model_heldout, _) = model_scores(&heldout_indices, &truth_heldout)?;
    let readout = DamageReadout::for_model(&outcome.splats, run.palette);
    let twin_train = evaluate_damage(&outcome.splats, &truth_train, &readout, run.background);
    let twin_heldout = evaluate_damage(&outcome.splats, &truth_heldout, &readout, run.background);

    // The first training view: the model's mask and the twin's, over the photo.
    if let (Some(&index), Some(truth)) = (train_indices.first(), truth_train.first()) {
        let loaded = dataset
            .load_view(index, run.scale)
            .map_err(|e| e.to_string())?;
        let truth_bits: Vec<bool> = truth.reference[0]
            .as_ref()
            .map(|m| m.iter_bool().collect())
            .unwrap_or_else(|| vec![false; loaded.image.pixel_count()]);
        let (_, masks) = dataset
            .load_view_masks(index, &segmented_source, run.scale)
            .map_err(|e| e.to_string())?;
        let model_bits: Vec<bool> = masks
            .get(&DamageClass::Crack)
            .map(|m| m.iter_bool().collect())
            .unwrap_or_else(|| vec![false; loaded.image.pixel_count()]);
        let (splats, readout) = readout.prepare(&outcome.splats);
        let mut out = RenderOutput::default();
        Rasterizer::new().forward(
            &splats,
            &truth.camera,
            &RenderSettings::new(run.background, splats.sh_degree),
            &mut out,
        );
        let twin_bits: Vec<bool> = predicted_masks(&out, &readout)[0].iter_bool().collect();
        for (name, bits) in [("model", &model_bits), ("twin", &twin_bits)] {
            write_overlay(
                &figures.join(format!("segment-overlay-demo-{name}.png")),
                &loaded.image,
                bits,
                &truth_bits,
            )
            .map_err(|e| e.to_string())?;
        }
    }

    let result = DemoResult {
        views: dataset.views.len(),
        width: config.demo_width,
        height: config.demo_height,
        iterations: config.demo_iterations,
        model_iou: crack(&model_train, MaskAgreement::iou),
        model_iou_per_view_mean: model_per_view,
        model_precision: crack(&model_train, MaskAgreement::precision),
        model_recall: crack(&model_train, MaskAgreement::recall),
        twin_iou: crack(&twin_train, MaskAgreement::iou),
        twin_precision: crack(&twin_train, MaskAgreement::precision),
        twin_recall: crack(&twin_train, MaskAgreement::recall),
        twin_heldout_iou: crack(&twin_heldout, MaskAgreement::iou),
        model_heldout_iou: crack(&model_heldout, MaskAgreement::iou),
        train_seconds: outcome.seconds,
    };
    on_line(format!(
        "crack IoU against the truth, training views: model {:.3} (per-view mean {:.3}), twin \
         {:.3}; held-out: model {:.3}, twin {:.3}",
        result.model_iou,
        result.model_iou_per_view_mean,
        result.twin_iou,
        result.model_heldout_iou,
        result.twin_heldout_iou
    ));
    Ok(result)
}

/// Runs `model` (one crack channel) on every photo of `dataset` at the photo's size and writes
/// `folder/masks/crack/` and `folder/probabilities/crack/`, replacing what is there.
pub fn segment_cracks_into(
    model: &SegmentModel,
    dataset: &Dataset,
    folder: &Path,
    threshold: f32,
) -> Result<SegmentSummary, String> {
    let settings = SegmentSettings {
        classes: vec![Some(DamageClass::Crack)],
        photo: PhotoSettings {
            preprocess: Preprocess::default(),
            scale: ImageScale::Factor(1),
            tiling: Tiling::default(),
        },
        threshold,
        overwrite: true,
        background: [0.0; 3],
    };
    segment_photos(
        model,
        folder,
        &dataset_photos(dataset),
        &settings,
        &mut |_, _| true,
    )
    .map_err(|e| e.to_string())
}

/// A crack figure of `scores` (0 when no view had a crack reference).
fn crack(scores: &DamageScores, figure: fn(&MaskAgreement) -> f64) -> f64 {
    scores.classes.get(&DamageClass::Crack).map_or(0.0, figure)
}
