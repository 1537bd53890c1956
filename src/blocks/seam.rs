//! The seam report of a merged model: on the held-out views (no block trained on them), the
//! photo PSNR and the damage IoU in a band around each inner block boundary against the rest of
//! the structure. A pixel is in the band when the surface it renders (its depth, where it is at
//! least 5 % opaque) lies within the band's half width of a boundary along the long axis;
//! background pixels and the rest of the surface are the rest.

use std::collections::BTreeMap;

use glam::Vec3;
use serde::Serialize;

use crate::blocks::plan::Plan;
use crate::blocks::surface::surface_along;
use crate::damage::assess::{EvalRequest, ModelScores, evaluate_model};
use crate::damage::evaluate::{DamageReadout, DamageScores, predicted_masks};
use crate::damage::reference::{load_reference_views, reference_source};
use crate::damage::setup::effective_mode;
use crate::damage::{Palette, TrainMode};
use crate::raster::{Rasterizer, RenderOutput, RenderSettings};
use crate::scene::{Camera, Dataset, Mask, SceneError};
use crate::splats::Splats;
use crate::train::views::{Holdout, load_views, split_views};

/// Scores of one part of the held-out pixels.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PartScores {
    pub pixels: u64,
    /// PSNR over the part's pixels of every held-out view (pooled squared error).
    pub psnr: Option<f64>,
    /// Per damage class, the IoU over the part's pixels (classes with reference pixels).
    pub damage_iou: BTreeMap<String, f64>,
}

/// The merged model on the held-out views: whole images as `eval` scores them, and the seam
/// band against the rest.
#[derive(Clone, Debug, Serialize)]
pub struct SeamReport {
    pub heldout_views: usize,
    pub band_half_width: f32,
    pub whole: ModelScores,
    pub band: PartScores,
    pub rest: PartScores,
}

/// Accumulates one part's squared error and damage agreement.
#[derive(Default)]
struct Part {
    squared_error: f64,
    pixels: u64,
    damage: DamageScores,
}

impl Part {
    fn scores(&self) -> PartScores {
        let figures = self.damage.figures();
        PartScores {
            pixels: self.pixels,
            psnr: (self.pixels > 0).then(|| {
                let mse = (self.squared_error / (3 * self.pixels) as f64).max(1e-12);
                -10.0 * mse.log10()
            }),
            damage_iou: figures.iou,
        }
    }
}

/// Scores `merged` (the merge of `plan`) on `dataset`'s held-out views.
pub fn seam_report(
    dataset: &Dataset,
    plan: &Plan,
    merged: &Splats,
) -> Result<SeamReport, SceneError> {
    let training = &plan.training;
    let scale = training
        .image_scale()
        .ok_or_else(|| SceneError::invalid(&plan.dataset, "the plan's scale is not a scale"))?;
    let background = Vec3::from_array(training.background);
    let holdout = Holdout::Auto {
        every: training.test_every,
    };
    let (_, heldout) =
        split_views(dataset, &holdout).map_err(|e| SceneError::invalid(&dataset.root, e))?;
    let mode = effective_mode(dataset, training.mode);
    let readout = DamageReadout {
        mode,
        ..DamageReadout::for_model(merged, Palette::default())
    };
    let whole = evaluate_model(
        dataset,
        merged,
        &EvalRequest {
            indices: heldout.clone(),
            scale,
            background,
            sh_degree: merged.sh_degree,
            photometric: true,
            half_appearance: false,
            readout,
        },
        &mut |_, _| {},
    )?;

    let views = load_views(dataset, &heldout, scale, false)?;
    let references = match reference_source(dataset) {
        Some(source) if mode != TrainMode::Rgb => {
            Some(load_reference_views(dataset, &source, &heldout, scale)?)
        }
        _ => None,
    };
    let (model, readout) = readout.prepare(merged);
    let settings = RenderSettings::new(background, merged.sh_degree);
    let boundaries = plan.boundaries();
    let mut rasterizer = Rasterizer::new();
    let mut out = RenderOutput::default();
    let (mut band, mut rest) = (Part::default(), Part::default());
    for (i, view) in views.iter().enumerate() {
        rasterizer.forward(&model, &view.camera, &settings, &mut out);
        let in_band = band_mask(&out, &view.camera, plan, &boundaries);
        let used = |p: usize| view.region.as_ref().is_none_or(|r| r.data[p] != 0);
        for (p, &b) in in_band.data.iter().enumerate() {
            if !used(p) {
                continue;
            }
            let error: f64 = (0..3)
                .map(|c| (out.color[p * 3 + c] as f64 - view.image.data[p * 3 + c] as f64).powi(2))
                .sum();
            let part = if b != 0 { &mut band } else { &mut rest };
            part.squared_error += error;
            part.pixels += 1;
        }
        if let Some(reference) = references.as_ref().map(|r| &r[i]) {
            let predicted = predicted_masks(&out, &readout);
            let mut rest_mask = in_band.clone();
            for v in &mut rest_mask.data {
                *v = u8::from(*v == 0);
            }
            for (part, mask) in [
                (&mut band, &mut in_band.clone()),
                (&mut rest, &mut rest_mask),
            ] {
                if let Some(ignore) = &reference.used {
                    for (m, u) in mask.data.iter_mut().zip(&ignore.data) {
                        *m &= u8::from(*u != 0);
                    }
                }
                part.damage
                    .add_view_where(&predicted, &reference.reference, Some(mask));
            }
        }
    }
    Ok(SeamReport {
        heldout_views: heldout.len(),
        band_half_width: plan.seam_band,
        whole,
        band: band.scores(),
        rest: rest.scores(),
    })
}

/// The pixels of a render whose surface lies within the plan's seam band of a boundary.
fn band_mask(out: &RenderOutput, camera: &Camera, plan: &Plan, boundaries: &[f32]) -> Mask {
    let mut mask = Mask::empty(out.width, out.height);
    for (p, along) in surface_along(out, camera, plan).into_iter().enumerate() {
        if along.is_some_and(|a| boundaries.iter().any(|b| (a - b).abs() <= plan.seam_band)) {
            mask.data[p] = 1;
        }
    }
    mask
}
