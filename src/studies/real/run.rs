//! The real-photo study's run: every stage on one stamped capture (`stamped/survey-1/`,
//! `survey-2/`), in the order an inspector's project goes through them.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use crate::damage::evaluate::{
    DamageReadout, DamageScores, ReferenceView, evaluate_damage, predicted_masks,
};
use crate::damage::measure::{MeasureConfig, measure_damage};
use crate::damage::reference::{ReferenceSource, load_reference_views, reference_source};
use crate::damage::refine::{RefineConfig, Strategy, refine_job};
use crate::damage::select::SelectConfig;
use crate::damage::setup::{RunConfig, prepare_run};
use crate::damage::{DamageClass, TrainMode};
use crate::raster::{Rasterizer, RenderOutput, RenderSettings};
use crate::scene::masks::count_masks;
use crate::scene::open::OpenOptions;
use crate::scene::{Dataset, ImageScale, Mask, MaskFolder};
use crate::segment::SegmentModel;
use crate::splats::Splats;
use crate::studies::real::pixels::{add_agreement, add_corrections, agreement, view_errors};
use crate::studies::real::quantities::{quantity_rows, read_truth};
use crate::studies::real::rows::{
    ClassFigures, Correction, RealStudy, RealStudyConfig, Refinement, SegmentedTwin, TwinFigures,
};
use crate::studies::segment::demo::segment_cracks_into;
use crate::timeline::changes::{DetectConfig, OLD_DAMAGE_THRESHOLD, detect};
use crate::timeline::detect_survey::DEFAULT_BAND_PX;
use crate::train::job::{JobError, JobOptions};
use crate::train::run::train;

/// The photos' own size: the segmenter's and the refinement's resolution.
const PHOTO_SCALE: ImageScale = ImageScale::Factor(1);

/// Where the segmenter's masks come from.
pub enum Segmenter<'a> {
    /// Run this crack model on every photo, writing into the folder (`masks/crack/`).
    Model(&'a SegmentModel, &'a Path),
    /// Masks a segmenter already wrote: `folder/masks/crack/<photo>.png` for every photo.
    Masks(&'a Path),
}

/// Runs the study on `stamped` (the output of `damage-twin stamp`). The twin on the truth masks
/// and what follows from it run first, the segmenter's masks last. `on_line` gets one progress
/// line per stage.
pub fn run_real(
    stamped: &Path,
    segmenter: Segmenter,
    segmenter_name: &str,
    config: &RealStudyConfig,
    threads: Option<usize>,
    on_line: &mut dyn FnMut(String),
) -> Result<RealStudy, String> {
    let survey1 = stamped.join("survey-1");
    let dataset = Dataset::open(&survey1, &OpenOptions::default()).map_err(|e| e.to_string())?;
    let source = reference_source(&dataset)
        .filter(|s| matches!(s, ReferenceSource::Truth(_)))
        .ok_or_else(|| {
            format!(
                "{}: no truth/masks (a capture stamped by `damage-twin stamp` has them)",
                survey1.display()
            )
        })?;
    let truth = read_truth(&survey1)?;
    // Given masks are checked before hours of training, not after.
    if let Segmenter::Masks(folder) = &segmenter {
        every_photo_has_a_crack_mask(&dataset, folder)?;
    }
    let metres = truth.metres_per_unit;
    let scale = ImageScale::Factor(config.scale.max(1));

    // §3: the label-mode twin on the stamped truth masks.
    let run = RunConfig {
        mode: TrainMode::Label,
        iterations: config.iterations,
        scale,
        ..RunConfig::default()
    };
    let (truth_model, truth_twin, (_, heldout_indices)) =
        train_label_twin(&dataset, &run, &source, threads)?;
    on_line(twin_line("twin on the truth masks", &truth_twin));
    let heldout_truth = load_reference_views(&dataset, &source, &heldout_indices, scale)
        .map_err(|e| e.to_string())?;
    let size = heldout_truth.first().map_or((0, 0), |v| {
        (v.camera.intrinsics.width, v.camera.intrinsics.height)
    });

    // Refinement: fine-tune at the photos' size, both scored there on the held-out views.
    let mut refinement_skipped = None;
    let (refinement, survey1_model) = if config.fine_iterations > 0 {
        match refine_twin(&dataset, &run, &source, &truth_model, config, threads)? {
            Ok((refinement, refined)) => {
                on_line(format!(
                    "fine-tune, {} steps in {:.0} s: held-out IoU at the photos' size {} → {}",
                    config.fine_iterations,
                    refinement.seconds,
                    ious(&refinement.coarse_heldout),
                    ious(&refinement.refined_heldout)
                ));
                (Some(refinement), refined)
            }
            // A twin with nothing to refine is a figure of this capture, not a failed study.
            Err(reason) => {
                on_line(format!("no fine-tune: {reason}"));
                refinement_skipped = Some(reason);
                (None, truth_model)
            }
        }
    } else {
        (None, truth_model)
    };

    // Change detection: survey 2 against survey 1's twin.
    let change = detect_changes(&stamped.join("survey-2"), &survey1_model, &run)?;
    on_line(format!(
        "change detection against survey 2: {}",
        change
            .iter()
            .map(|c| format!("{} P {:.3} R {:.3}", c.class, c.precision, c.recall))
            .collect::<Vec<_>>()
            .join(", ")
    ));

    // The report's quantities: survey 1's twin measured in metres against the truth.
    let cameras: Vec<_> = dataset.views.iter().map(|v| v.camera).collect();
    let measured = measure_damage(&survey1_model, &cameras, &MeasureConfig::for_scale(metres));
    let quantities = quantity_rows(&truth.totals, &measured, metres);
    for row in &quantities {
        on_line(format!(
            "{}: truth {:.3}, measured {:.3} ({:+.1} %)",
            row.quantity,
            row.truth,
            row.measured,
            100.0 * row.relative_error
        ));
    }

    // §2: the crack model on every photo, at the photo's size, against the stamped truth.
    let (segmented, segmenter_seconds) = match segmenter {
        Segmenter::Model(model, folder) => {
            let started = Instant::now();
            let summary = segment_cracks_into(model, &dataset, folder, config.threshold)?;
            let seconds = started.elapsed().as_secs_f64();
            on_line(format!(
                "segmented {} photos in {seconds:.0} s: {:.3} % of pixels marked crack",
                summary.photos,
                100.0 * summary.damage_fraction.get("crack").copied().unwrap_or(0.0)
            ));
            (folder.to_path_buf(), Some(seconds))
        }
        Segmenter::Masks(folder) => (folder.to_path_buf(), None),
    };
    let segmented_masks = MaskFolder::new(segmented.join("masks"));
    let all: Vec<usize> = (0..dataset.views.len()).collect();
    let photo_truth =
        load_reference_views(&dataset, &source, &all, PHOTO_SCALE).map_err(|e| e.to_string())?;
    let mut segmenter_views = Vec::new();
    let mut pooled = crate::metrics::MaskAgreement::default();
    for (&index, truth_view) in all.iter().zip(&photo_truth) {
        let marked = crack_mask(&dataset, index, &segmented_masks, PHOTO_SCALE, truth_view)?;
        let truth_crack = crack_truth(truth_view);
        add_agreement(&mut pooled, &agreement(&marked, &truth_crack));
        segmenter_views.push(view_errors(&truth_view.name, &marked, &truth_crack));
    }
    drop(photo_truth);
    let segmenter_pooled = ClassFigures::new("crack", &pooled);
    on_line(format!(
        "crack model against the truth, pooled over {} photos: IoU {:.3}, precision {:.3}, \
         recall {:.3}",
        all.len(),
        segmenter_pooled.iou,
        segmenter_pooled.precision,
        segmenter_pooled.recall
    ));

    // The twin on the crack model's masks (crack only: the model knows no other class).
    let mut segmented_dataset = dataset.clone();
    segmented_dataset.masks = Some(MaskFolder::shared(segmented.join("masks")));
    segmented_dataset.mask_counts = count_masks(&segmented.join("masks"));
    let segmented_twin =
        segmented_twin_figures(&segmented_dataset, &run, &source, &segmented_masks, threads)?;
    on_line(format!(
        "twin on the model's masks: crack IoU on its training views {:.3} (the model's {:.3}), \
         held out {:.3}; {:.1} % of the model's wrong pixels corrected, {:.2} % of its right ones \
         broken",
        first_iou(&segmented_twin.twin.train),
        segmented_twin.model_train.iou,
        first_iou(&segmented_twin.twin.heldout),
        100.0 * segmented_twin.corrected_share,
        100.0 * segmented_twin.introduced_share
    ));

    Ok(RealStudy {
        config: config.clone(),
        stamped: stamped.display().to_string(),
        model: segmenter_name.to_string(),
        metres_per_unit: metres,
        views: dataset.views.len(),
        heldout_views: heldout_indices.len(),
        width: size.0,
        height: size.1,
        segmenter_views,
        segmenter_pooled,
        segmenter_seconds,
        truth_twin,
        refinement,
        refinement_skipped,
        segmented_twin,
        change,
        quantities,
    })
}

type TrainedTwin = (Splats, TwinFigures, (Vec<usize>, Vec<usize>));

/// Trains a label-mode twin on `dataset`'s masks and scores it against the truth on its
/// training and held-out views.
fn train_label_twin(
    dataset: &Dataset,
    run: &RunConfig,
    source: &ReferenceSource,
    threads: Option<usize>,
) -> Result<TrainedTwin, String> {
    let prepared = prepare_run(dataset, run).map_err(|e| e.to_string())?;
    let indices = (
        prepared.train_indices.clone(),
        prepared.heldout_indices.clone(),
    );
    let outcome = train(prepared.setup, JobOptions::headless(threads))
        .wait()
        .map_err(|e| e.to_string())?;
    let readout = DamageReadout::for_model(&outcome.splats, run.palette);
    let score = |indices: &[usize]| -> Result<DamageScores, String> {
        let views =
            load_reference_views(dataset, source, indices, run.scale).map_err(|e| e.to_string())?;
        Ok(evaluate_damage(
            &outcome.splats,
            &views,
            &readout,
            run.background,
        ))
    };
    let figures = TwinFigures {
        train: ClassFigures::of(&score(&indices.0)?),
        heldout: ClassFigures::of(&score(&indices.1)?),
        seconds: outcome.seconds,
        gaussians: outcome.splats.len(),
    };
    Ok((Arc::unwrap_or_clone(outcome.splats), figures, indices))
}

/// The hierarchical refinement (selection, hulls, fine-tune inside them) at the photos' size;
/// the coarse and the refined twin scored there on the held-out views. `Ok(Err(reason))` when
/// the refinement refuses the twin (nothing selected).
fn refine_twin(
    dataset: &Dataset,
    run: &RunConfig,
    source: &ReferenceSource,
    coarse: &Splats,
    config: &RealStudyConfig,
    threads: Option<usize>,
) -> Result<Result<(Refinement, Splats), String>, String> {
    let refine_config = RefineConfig {
        select: SelectConfig {
            mode: TrainMode::Label,
            ..SelectConfig::default()
        },
        strategy: Strategy::Finetune,
        scale: PHOTO_SCALE,
        select_scale: run.scale,
        iterations: config.fine_iterations,
        holdout: run.holdout.clone(),
        background: run.background,
        seed: run.seed,
        ..RefineConfig::default()
    };
    let started = Instant::now();
    let outcome = refine_job(
        Arc::new(dataset.clone()),
        Arc::new(coarse.clone()),
        refine_config,
        JobOptions::headless(threads),
    )
    .wait();
    let outcome = match outcome {
        Ok(outcome) => outcome,
        // The refinement refuses a twin it cannot refine (no damage Gaussians selected).
        Err(JobError::Invalid(reason)) => return Ok(Err(reason)),
        Err(e) => return Err(format!("fine-tune: {e}")),
    };
    let seconds = started.elapsed().as_secs_f64();
    let prepared = prepare_run(dataset, run).map_err(|e| e.to_string())?;
    let heldout = load_reference_views(dataset, source, &prepared.heldout_indices, PHOTO_SCALE)
        .map_err(|e| e.to_string())?;
    let score = |splats: &Splats| {
        let readout = DamageReadout::for_model(splats, run.palette);
        ClassFigures::of(&evaluate_damage(splats, &heldout, &readout, run.background))
    };
    let refinement = Refinement {
        coarse_heldout: score(coarse),
        refined_heldout: score(&outcome.splats),
        seconds,
    };
    Ok(Ok((refinement, Arc::unwrap_or_clone(outcome.splats))))
}

/// The twin trained on the crack model's masks, and the model's masks, against the truth at the
/// training scale; the corrections on the training views.
fn segmented_twin_figures(
    dataset: &Dataset,
    run: &RunConfig,
    source: &ReferenceSource,
    segmented: &MaskFolder,
    threads: Option<usize>,
) -> Result<SegmentedTwin, String> {
    let (splats, twin, (train_indices, heldout_indices)) =
        train_label_twin(dataset, run, source, threads)?;
    let readout = DamageReadout::for_model(&splats, run.palette);
    let (prepared, readout) = readout.prepare(&splats);
    let settings = RenderSettings::new(run.background, prepared.sh_degree);
    let mut rasterizer = Rasterizer::new();
    let mut out = RenderOutput::default();
    let mut correction = Correction::default();
    let mut model_scores = |indices: &[usize], with_twin: bool| -> Result<ClassFigures, String> {
        let views =
            load_reference_views(dataset, source, indices, run.scale).map_err(|e| e.to_string())?;
        let mut pooled = crate::metrics::MaskAgreement::default();
        for (&index, view) in indices.iter().zip(&views) {
            let marked = crack_mask(dataset, index, segmented, run.scale, view)?;
            let truth = crack_truth(view);
            add_agreement(&mut pooled, &agreement(&marked, &truth));
            if with_twin {
                rasterizer.forward(&prepared, &view.camera, &settings, &mut out);
                let rendered = &predicted_masks(&out, &readout)[DamageClass::Crack.channel()];
                add_corrections(&mut correction, &truth, &marked, rendered);
            }
        }
        Ok(ClassFigures::new("crack", &pooled))
    };
    let model_train = model_scores(&train_indices, true)?;
    let model_heldout = model_scores(&heldout_indices, false)?;
    Ok(SegmentedTwin {
        model_train,
        model_heldout,
        twin,
        corrected_share: correction.corrected_share(),
        introduced_share: correction.introduced_share(),
        correction,
    })
}

/// Survey 2's new damage against `twin` with `twin detect`'s defaults, per class with truth.
fn detect_changes(
    survey2: &Path,
    twin: &Splats,
    run: &RunConfig,
) -> Result<Vec<ClassFigures>, String> {
    let dataset = Dataset::open(survey2, &OpenOptions::default()).map_err(|e| e.to_string())?;
    let config = DetectConfig {
        scale: run.scale,
        readout: DamageReadout::for_model(twin, run.palette),
        background: run.background,
        band_px: DEFAULT_BAND_PX,
        min_area_px: 0,
        vote: false,
        old_threshold: OLD_DAMAGE_THRESHOLD,
    };
    let detection =
        detect(twin, &dataset, &config, None, &mut |_, _| {}).map_err(|e| e.to_string())?;
    let Some(step) = detection.summary() else {
        return Ok(Vec::new());
    };
    Ok(step
        .truth_pixels
        .iter()
        .filter(|(_, pixels)| **pixels > 0)
        .map(|(class, &truth_pixels)| ClassFigures {
            class: class.clone(),
            iou: step.iou.get(class).copied().unwrap_or(f64::NAN),
            precision: step.precision.get(class).copied().unwrap_or(f64::NAN),
            recall: step.recall.get(class).copied().unwrap_or(f64::NAN),
            truth_pixels,
        })
        .collect())
}

/// Refuses a folder of masks that lacks a photo's crack mask (an unfinished segmentation
/// would score as a segmenter that marked nothing), naming the first.
fn every_photo_has_a_crack_mask(dataset: &Dataset, folder: &Path) -> Result<(), String> {
    let cracks = folder.join("masks").join(DamageClass::Crack.id());
    for view in &dataset.views {
        let path = cracks.join(format!("{}.png", view.name));
        if !path.is_file() {
            return Err(format!(
                "{}: missing; the segmenter's masks must cover every photo of {}",
                path.display(),
                dataset.root.display()
            ));
        }
    }
    Ok(())
}

/// The model's crack mask of view `index` at `scale` (empty where it wrote none).
fn crack_mask(
    dataset: &Dataset,
    index: usize,
    segmented: &MaskFolder,
    scale: ImageScale,
    truth: &ReferenceView,
) -> Result<Mask, String> {
    let (_, mut masks) = dataset
        .load_view_masks(index, segmented, scale)
        .map_err(|e| e.to_string())?;
    Ok(masks.remove(&DamageClass::Crack).unwrap_or_else(|| {
        Mask::empty(
            truth.camera.intrinsics.width,
            truth.camera.intrinsics.height,
        )
    }))
}

/// The truth's crack mask of a reference view (empty when it has none).
fn crack_truth(view: &ReferenceView) -> Mask {
    view.reference[DamageClass::Crack.channel()]
        .clone()
        .unwrap_or_else(|| Mask::empty(view.camera.intrinsics.width, view.camera.intrinsics.height))
}

fn first_iou(figures: &[ClassFigures]) -> f64 {
    figures.first().map_or(f64::NAN, |f| f.iou)
}

fn ious(figures: &[ClassFigures]) -> String {
    figures
        .iter()
        .map(|f| format!("{} {:.3}", f.class, f.iou))
        .collect::<Vec<_>>()
        .join(" / ")
}

fn twin_line(what: &str, twin: &TwinFigures) -> String {
    format!(
        "{what}: {} Gaussians, {:.0} s; IoU train {}; held out {}",
        twin.gaussians,
        twin.seconds,
        ious(&twin.train),
        ious(&twin.heldout)
    )
}
