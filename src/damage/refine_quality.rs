//! What a refinement is scored by: damage and image quality on the held-out views at the
//! refinement scale (`Quality`), and the cost of the same step on uncropped views, the figure
//! the hull crops are measured against.

use std::collections::BTreeMap;

use glam::Vec3;
use serde::Serialize;

use crate::damage::DamageClass;
use crate::damage::TrainMode;
use crate::damage::evaluate::{
    DamageReadout, DamageScores, ReferenceView, evaluate_damage, score_render,
};
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

/// What a refinement step costs against a full-image step of the same model, timed
/// interleaved in one process (rounds of one step per view of each), so the host's load falls
/// on both alike and their ratio holds on a busy machine; with the pixel counts of the two,
/// which no load changes.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StepCosts {
    /// The views both were timed on (up to four of the trained ones).
    pub views: usize,
    /// Timed steps of each.
    pub steps: u32,
    /// Refinement steps (hull crops, focused) and full-image steps, by stage.
    pub refine_ms: StageTimes,
    pub full_ms: StageTimes,
    /// `refine_ms.total / full_ms.total`.
    pub share: f64,
    /// Per step, on average over the views: the pixels a full-image step renders, the loss
    /// region's pixels (all a refinement step blends), the pixels of the tiles holding them,
    /// and the pixels the region's SSIM reads (its pieces with their margins).
    pub full_pixels: f64,
    pub region_pixels: f64,
    pub region_tile_pixels: f64,
    pub ssim_pixels: f64,
}

/// [`StepCosts`] of the run `spec` on the crops `crops` of the views `trained` (in the same
/// order), against the same views uncropped (made into targets by `targets` as the crops were).
#[allow(clippy::too_many_arguments)]
pub(super) fn step_costs(
    focus: &Focus,
    model: &Splats,
    spec: &TrainSpec,
    trained: &[&ViewHulls],
    crops: &[TrainView],
    targets: &(dyn Fn(&mut [TrainView]) + Sync),
    mode: TrainMode,
    rounds: u32,
) -> Result<StepCosts, JobError> {
    const VIEWS: usize = 4;
    let indices: Vec<usize> = trained.iter().take(VIEWS).map(|v| v.index).collect();
    let views = focus.load(&indices, mode.uses_masks(), targets)?;
    let crops: Vec<TrainView> = crops.iter().take(indices.len()).cloned().collect();
    let mut costs = StepCosts {
        views: indices.len(),
        ..StepCosts::default()
    };
    for (full, crop) in views.iter().zip(&crops) {
        costs.full_pixels += f64::from(full.image.width) * f64::from(full.image.height);
        if let Some(region) = &crop.region {
            let counts = region_counts(region);
            costs.region_pixels += counts.0;
            costs.region_tile_pixels += counts.1;
            costs.ssim_pixels += counts.2;
        }
    }
    let per_view = 1.0 / indices.len().max(1) as f64;
    costs.full_pixels *= per_view;
    costs.region_pixels *= per_view;
    costs.region_tile_pixels *= per_view;
    costs.ssim_pixels *= per_view;
    // One warm-up round (buffers sized, each view's frozen cache filled), then the timed ones.
    let steps = indices.len() as u32 * (rounds + 1);
    let timing_spec = TrainSpec {
        iterations: steps,
        densify: DensifyPolicy::Off,
        ..spec.clone()
    };
    // The same spec for both (the full-image step keeps the run's trainable set, as the
    // figures before this comparison did): only the crops and their regions differ.
    let mut refine = Trainer::new(timing_spec.clone(), model.clone(), crops)?;
    let mut full = Trainer::new(timing_spec, model.clone(), views)?;
    let (mut refine_warm, mut full_warm) = (StageTimes::default(), StageTimes::default());
    for round in 0..=rounds {
        for _ in 0..indices.len() {
            refine.step();
        }
        for _ in 0..indices.len() {
            full.step();
        }
        if round == 0 {
            refine_warm = refine.timings().clone();
            full_warm = full.timings().clone();
        }
    }
    let timed = indices.len() as u32 * rounds;
    let mut refine_times = refine.timings().clone();
    refine_times.subtract(&refine_warm);
    let mut full_times = full.timings().clone();
    full_times.subtract(&full_warm);
    costs.steps = timed;
    costs.refine_ms = refine_times.per_step_ms(timed);
    costs.full_ms = full_times.per_step_ms(timed);
    costs.share = costs.refine_ms.total / costs.full_ms.total.max(f64::MIN_POSITIVE);
    Ok(costs)
}

/// A loss region's pixels, the pixels of its tiles, and those its SSIM reads.
fn region_counts(region: &crate::scene::Mask) -> (f64, f64, f64) {
    let ts = crate::raster::TILE_SIZE as usize;
    let rows = crate::raster::pixel_rows(&region.data, region.width, region.height);
    let pixels: u32 = rows.iter().map(|r| r.count_ones()).sum();
    let tiles_x = crate::raster::tile_grid(region.width, region.height).0 as usize;
    let (w, h) = (region.width as usize, region.height as usize);
    // The tiles' pixels inside the image (edge tiles are cut by its border).
    let tile_pixels: usize = rows
        .chunks_exact(ts)
        .enumerate()
        .filter(|(_, tile)| tile.iter().any(|&r| r != 0))
        .map(|(t, _)| {
            let (x0, y0) = ((t % tiles_x) * ts, (t / tiles_x) * ts);
            (w - x0).min(ts) * (h - y0).min(ts)
        })
        .sum();
    let mut weights = Vec::new();
    crate::train::loss::mask_weights(region, &mut weights);
    let read =
        crate::train::ssim::RegionSsim::new().pixels_read(&weights, region.width, region.height);
    let whole = region.width as usize * region.height as usize;
    (
        f64::from(pixels),
        tile_pixels as f64,
        read.min(whole) as f64,
    )
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
    let references = match reference_source(focus.dataset) {
        Some(source) => Some(load_reference_views(
            focus.dataset,
            &source,
            &indices,
            focus.scale,
        )?),
        None => None,
    };
    let photos = focus.load(&indices, false, &|_| {})?;
    // One render per view serves the damage scores and the PSNR where the readout reads the
    // model as it is and the reference views' cameras are the photos' (always, at one scale):
    // the second render of each view was the same bit for bit.
    let (prepared, _) = readout.prepare(splats);
    let share = matches!(prepared, std::borrow::Cow::Borrowed(_))
        && references.as_ref().is_some_and(|views| {
            views
                .iter()
                .zip(&photos)
                .all(|(view, photo)| view.camera == photo.camera)
        });
    let mut shared_scores = DamageScores::default();
    if let Some(views) = references.as_ref().filter(|_| !share) {
        let figures = evaluate_damage(splats, views, readout, background).figures();
        q.iou = figures.iou;
        q.precision = figures.precision;
        q.recall = figures.recall;
    }
    let settings = RenderSettings::new(background, splats.sh_degree);
    let (mut se_out, mut n_out, mut se_all, mut n_all) = (0.0f64, 0usize, 0.0f64, 0usize);
    for (i, (photo, v)) in photos.iter().zip(heldout).enumerate() {
        let out = render(splats, &photo.camera, &settings);
        if let Some(views) = references.as_ref().filter(|_| share) {
            score_render(&mut shared_scores, &out, &views[i], readout);
        }
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
    if share {
        let figures = shared_scores.figures();
        q.iou = figures.iou;
        q.precision = figures.precision;
        q.recall = figures.recall;
    }
    let psnr = |se: f64, n: usize| (n > 0).then(|| -10.0 * (se / n as f64).max(1e-12).log10());
    q.psnr_outside_hulls = psnr(se_out, n_out);
    q.psnr = psnr(se_all, n_all);
    Ok(q)
}
