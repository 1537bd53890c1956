//! What a refinement is scored by: damage and image quality on the held-out views at the
//! refinement scale (`Quality`), and the cost of the same step on uncropped views, the figure
//! the hull crops are measured against.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::Vec3;
use serde::Serialize;

use crate::damage::DamageClass;
use crate::damage::TrainMode;
use crate::damage::evaluate::{DamageReadout, ReferenceView, evaluate_damage};
use crate::damage::reference::{load_reference_views, reference_source};
use crate::raster::{RenderSettings, render};
use crate::splats::Splats;
use crate::train::focus::{Focus, ViewHulls};
use crate::train::job::JobError;
use crate::train::spec::{DensifyPolicy, TrainSpec, TrainView};
use crate::train::trainer::{StageTimes, Trainer};

/// Damage and image quality on the held-out views at the refinement scale.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Quality {
    pub iou: BTreeMap<String, f64>,
    pub precision: BTreeMap<String, f64>,
    pub recall: BTreeMap<String, f64>,
    /// PSNR over the held-out pixels outside every hull (where nothing should change).
    pub psnr_outside_hulls: Option<f64>,
    /// PSNR over whole held-out images.
    pub psnr: Option<f64>,
}

/// Milliseconds per step of the same run on uncropped views (up to four of the trained ones),
/// made into targets by `targets` as the crops were, in all and by stage.
pub(super) fn full_step_ms(
    focus: &Focus,
    model: &Splats,
    spec: &TrainSpec,
    trained: &[&ViewHulls],
    targets: &(dyn Fn(&mut [TrainView]) + Sync),
    mode: TrainMode,
) -> Result<(f64, StageTimes), JobError> {
    const STEPS: u32 = 8;
    let indices: Vec<usize> = trained.iter().take(4).map(|v| v.index).collect();
    let views = focus.load(&indices, mode.uses_masks(), targets)?;
    let timing_spec = TrainSpec {
        iterations: STEPS,
        densify: DensifyPolicy::Off,
        ..spec.clone()
    };
    let mut trainer = Trainer::new(timing_spec, model.clone(), views)?;
    // One warm-up step sizes the buffers.
    trainer.step();
    let warm_up = trainer.timings().clone();
    let t = Instant::now();
    while !trainer.is_done() {
        trainer.step();
    }
    let ms = t.elapsed().as_secs_f64() * 1000.0 / (STEPS - 1) as f64;
    let mut stages = trainer.timings().clone();
    stages.subtract(&warm_up);
    Ok((ms, stages.per_step_ms(STEPS - 1)))
}

/// Per damage class, the share of the held-out views' reference pixels that lie inside the hulls
/// drawn there (None without reference masks). Pixels outside every hull are never trained, so
/// this bounds the refinement's recall: an update whose hulls miss new damage cannot learn it.
pub(super) fn hull_coverage(
    focus: &Focus,
    heldout: &[&ViewHulls],
) -> Result<Option<BTreeMap<String, f64>>, JobError> {
    let Some(source) = reference_source(focus.dataset) else {
        return Ok(None);
    };
    let indices: Vec<usize> = heldout.iter().map(|v| v.index).collect();
    let views = load_reference_views(focus.dataset, &source, &indices, focus.scale)?;
    Ok(Some(coverage_of(&views, heldout)))
}

/// `hull_coverage` of loaded reference views, each paired with its view's hulls; a class with
/// no reference pixel is left out.
fn coverage_of(views: &[ReferenceView], hulls: &[&ViewHulls]) -> BTreeMap<String, f64> {
    let mut counts = [(0usize, 0usize); DamageClass::ALL.len()];
    for (view, drawn) in views.iter().zip(hulls) {
        let inside = drawn.union();
        for (k, reference) in view.reference.iter().enumerate() {
            let Some(reference) = reference else {
                continue;
            };
            for (p, &r) in reference.data.iter().enumerate() {
                let used = view.used.as_ref().is_none_or(|u| u.data[p] != 0);
                if r != 0 && used {
                    counts[k].1 += 1;
                    counts[k].0 += usize::from(inside.data.get(p).is_some_and(|&h| h != 0));
                }
            }
        }
    }
    DamageClass::ALL
        .iter()
        .zip(counts)
        .filter(|(_, (_, total))| *total > 0)
        .map(|(class, (hit, total))| (class.id().to_string(), hit as f64 / total as f64))
        .collect()
}

/// Damage figures against the reference masks and PSNR (whole and outside the hulls) on the
/// held-out views at the refinement scale.
pub(super) fn quality(
    focus: &Focus,
    splats: &Splats,
    heldout: &[&ViewHulls],
    background: Vec3,
    readout: &DamageReadout,
) -> Result<Quality, JobError> {
    let indices: Vec<usize> = heldout.iter().map(|v| v.index).collect();
    let mut q = Quality::default();
    if indices.is_empty() {
        return Ok(q);
    }
    if let Some(source) = reference_source(focus.dataset) {
        let views = load_reference_views(focus.dataset, &source, &indices, focus.scale)?;
        let figures = evaluate_damage(splats, &views, readout, background).figures();
        q.iou = figures.iou;
        q.precision = figures.precision;
        q.recall = figures.recall;
    }
    let photos = focus.load(&indices, false, &|_| {})?;
    let settings = RenderSettings::new(background, splats.sh_degree);
    let (mut se_out, mut n_out, mut se_all, mut n_all) = (0.0f64, 0usize, 0.0f64, 0usize);
    for (photo, v) in photos.iter().zip(heldout) {
        let out = render(splats, &photo.camera, &settings);
        let inside = v.union();
        for (p, (rgb, target)) in out
            .color
            .chunks_exact(3)
            .zip(photo.image.data.chunks_exact(3))
            .enumerate()
        {
            let se: f64 = rgb
                .iter()
                .zip(target)
                .map(|(a, b)| f64::from(a - b).powi(2))
                .sum();
            se_all += se;
            n_all += 3;
            if inside.data[p] == 0 {
                se_out += se;
                n_out += 3;
            }
        }
    }
    let psnr = |se: f64, n: usize| (n > 0).then(|| -10.0 * (se / n as f64).max(1e-12).log10());
    q.psnr_outside_hulls = psnr(se_out, n_out);
    q.psnr = psnr(se_all, n_all);
    Ok(q)
}
