//! Change detection (the paper's §2.4): the twin, rendered from each pose of a later survey,
//! shows the damage it knows; damage in the new survey's masks that the render does not show is
//! new. Misregistration and blur leave thin false changes along old damage, and a coarse twin
//! misses some old damage outright, so up to four steps clean the raw difference, each
//! measured: a tolerance band around old damage, a minimum area, the earlier survey's own masks
//! at the same surface points (`earlier`), and a vote in 3D (candidate pixels lifted to the
//! twin's Gaussians must agree across the views that see them).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::damage::DamageClass;
use crate::damage::evaluate::{DamageReadout, LABEL_THRESHOLD, predicted_masks_at};
use crate::metrics::MaskAgreement;
use crate::raster::weight_lift::WeightLift;
use crate::raster::{RenderSettings, render};
use crate::scene::{Camera, Dataset, ImageScale, Mask, MaskFolder, MaskSource, SceneError};
use crate::splats::Splats;
use crate::timeline::earlier::{EarlierSurvey, surface_depth};
use crate::timeline::near_floaters::leaving_out_near_floaters;

/// How changes are found.
#[derive(Clone, Debug, PartialEq)]
pub struct DetectConfig {
    pub scale: ImageScale,
    pub readout: DamageReadout,
    pub background: glam::Vec3,
    /// New blobs lying wholly within this many pixels of old damage of their class are old
    /// damage seen shifted (misregistration, blur); growth reaching beyond the band stays.
    pub band_px: u32,
    /// New-damage blobs smaller than this many pixels are dropped.
    pub min_area_px: usize,
    /// Keep only candidates the views agree on in 3D.
    pub vote: bool,
    /// Label mode: the class probability above which the twin's render counts as old damage.
    /// Lowering it counts damage the twin shows only faintly from a new pose as old; on the
    /// demo it trades rebar and spalling recall for crack precision (docs/TIMELINE.md).
    pub old_threshold: f32,
}

/// The class probability above which the twin's render counts as old damage by default: the
/// evaluation's own threshold.
pub const OLD_DAMAGE_THRESHOLD: f32 = LABEL_THRESHOLD;

/// One view's masks per class (`DamageClass::ALL` order).
#[derive(Clone, Debug)]
pub struct ViewChanges {
    pub name: String,
    pub index: usize,
    /// What the twin renders there.
    pub old: Vec<Mask>,
    /// What the new survey's masks show.
    pub observed: Vec<Mask>,
    /// Observed and not rendered: new damage, after every cleaning step.
    pub new: Vec<Mask>,
    /// Rendered and not observed: damage no longer seen.
    pub gone: Vec<Mask>,
}

/// New-damage pixels per class after one step, and their agreement with the truth.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StepScores {
    pub step: String,
    pub pixels: BTreeMap<String, u64>,
    /// Present where the survey has `truth/new-damage`.
    pub precision: BTreeMap<String, f64>,
    pub recall: BTreeMap<String, f64>,
    pub f1: BTreeMap<String, f64>,
    pub iou: BTreeMap<String, f64>,
    pub truth_pixels: BTreeMap<String, u64>,
}

/// The detection's result.
#[derive(Clone, Debug)]
pub struct Detection {
    pub views: Vec<ViewChanges>,
    /// Raw difference, then after the band, the area filter and the vote.
    pub steps: Vec<StepScores>,
}

impl Detection {
    /// The final step's figures.
    pub fn summary(&self) -> Option<&StepScores> {
        self.steps.last()
    }
}

pub(super) fn dilate(mask: &Mask, r: u32) -> Mask {
    if r == 0 {
        return mask.clone();
    }
    let (w, h) = (mask.width as i64, mask.height as i64);
    let r = r as i64;
    let mut out = Mask::empty(mask.width, mask.height);
    for y in 0..h {
        for x in 0..w {
            if mask.data[(y * w + x) as usize] == 0 {
                continue;
            }
            for yy in (y - r).max(0)..=(y + r).min(h - 1) {
                for xx in (x - r).max(0)..=(x + r).min(w - 1) {
                    if (xx - x).pow(2) + (yy - y).pow(2) <= r * r {
                        out.data[(yy * w + xx) as usize] = 1;
                    }
                }
            }
        }
    }
    out
}

/// Drops 8-connected blobs of fewer than `min_area` pixels.
pub(super) fn drop_small(mask: &Mask, min_area: usize) -> Mask {
    drop_blobs(mask, |blob| blob.len() < min_area)
}

/// Drops the 8-connected blobs of `new` that lie wholly inside `band`: thin slivers along old
/// damage that misregistration and blur leave, while growth that reaches beyond the band is
/// kept whole (its pixels next to the old damage included).
pub(super) fn drop_slivers(new: &Mask, band: &Mask) -> Mask {
    drop_blobs(new, |blob| blob.iter().all(|&p| band.data[p] != 0))
}

/// Drops the 8-connected blobs (pixel indices) for which `drop` is true.
fn drop_blobs(mask: &Mask, drop: impl Fn(&[usize]) -> bool) -> Mask {
    let (w, h) = (mask.width as usize, mask.height as usize);
    let mut out = mask.clone();
    let mut seen = vec![false; w * h];
    let mut stack = Vec::new();
    let mut blob = Vec::new();
    for start in 0..w * h {
        if out.data[start] == 0 || seen[start] {
            continue;
        }
        blob.clear();
        stack.push(start);
        seen[start] = true;
        while let Some(p) = stack.pop() {
            blob.push(p);
            let (x, y) = ((p % w) as i64, (p / w) as i64);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                        continue;
                    }
                    let q = ny as usize * w + nx as usize;
                    if out.data[q] != 0 && !seen[q] {
                        seen[q] = true;
                        stack.push(q);
                    }
                }
            }
        }
        if drop(&blob) {
            for &p in &blob {
                out.data[p] = 0;
            }
        }
    }
    out
}

pub(super) fn and_not(a: &Mask, b: &Mask) -> Mask {
    Mask {
        width: a.width,
        height: a.height,
        data: a
            .data
            .iter()
            .zip(&b.data)
            .map(|(&x, &y)| u8::from(x != 0 && y == 0))
            .collect(),
    }
}

/// Scores per class of `new` masks (per view, per class) against the truth, if any.
fn score(step: &str, new: &[Vec<Mask>], truth: &[Option<Vec<Option<Mask>>>]) -> StepScores {
    let mut scores = StepScores {
        step: step.to_string(),
        ..StepScores::default()
    };
    let mut agreement: BTreeMap<DamageClass, MaskAgreement> = BTreeMap::new();
    for (v, masks) in new.iter().enumerate() {
        for (class, mask) in DamageClass::ALL.iter().zip(masks) {
            *scores.pixels.entry(class.id().to_string()).or_default() += mask.count() as u64;
            if let Some(Some(t)) = truth[v].as_ref().map(|t| &t[class.channel()]) {
                agreement.entry(*class).or_default().accumulate(
                    mask.data.iter().map(|&p| p != 0),
                    t.data.iter().map(|&p| p != 0),
                );
            }
        }
    }
    for (class, a) in agreement {
        let id = class.id().to_string();
        scores.precision.insert(id.clone(), a.precision());
        scores.recall.insert(id.clone(), a.recall());
        scores.f1.insert(id.clone(), a.f1());
        scores.iou.insert(id.clone(), a.iou());
        scores
            .truth_pixels
            .insert(id, a.true_positive + a.false_negative);
    }
    scores
}

/// Finds new damage of `dataset`'s views (a later survey, placed in the twin's frame) against
/// the `twin` model; `on_view(done, total)` reports progress.
///
/// With `earlier` (the previous survey's masks, `EarlierSurvey`), candidates that survey already
/// showed at the same surface point are dropped as old damage the twin failed to learn.
pub fn detect(
    twin: &Splats,
    dataset: &Dataset,
    config: &DetectConfig,
    earlier: Option<&EarlierSurvey>,
    on_view: &mut dyn FnMut(usize, usize),
) -> Result<Detection, SceneError> {
    let masks = dataset
        .masks
        .clone()
        .ok_or_else(|| SceneError::invalid(&dataset.root, "no damage masks to compare with"))?;
    let truth_folder = MaskFolder::new(dataset.root.join("truth").join("new-damage"));
    let settings = RenderSettings::new(config.background, twin.sh_degree);
    let total = dataset.views.len();
    let mut views = Vec::with_capacity(total);
    let mut truth = Vec::with_capacity(total);
    let mut cameras: Vec<Camera> = Vec::with_capacity(total);
    let mut depths: Vec<Vec<f32>> = Vec::with_capacity(total);
    for index in 0..total {
        let (camera, mut observed) =
            dataset.load_view_masks(index, masks.as_ref(), config.scale)?;
        let k = camera.intrinsics;
        let out = render(
            twin,
            &camera,
            &leaving_out_near_floaters(twin, &camera, &settings),
        );
        let old = predicted_masks_at(&out, &config.readout, config.old_threshold);
        if earlier.is_some() {
            depths.push(surface_depth(&out));
        }
        let observed: Vec<Mask> = DamageClass::ALL
            .iter()
            .map(|c| {
                observed
                    .remove(c)
                    .unwrap_or_else(|| Mask::empty(k.width, k.height))
            })
            .collect();
        truth.push(if truth_folder.is_available() {
            let (_, mut t) = dataset.load_view_masks(index, &truth_folder, config.scale)?;
            Some(
                DamageClass::ALL
                    .iter()
                    .map(|c| {
                        t.remove(c)
                            .map(Some)
                            .unwrap_or_else(|| Some(Mask::empty(k.width, k.height)))
                    })
                    .collect::<Vec<_>>(),
            )
        } else {
            None
        });
        let new = observed
            .iter()
            .zip(&old)
            .map(|(o, r)| and_not(o, r))
            .collect();
        let gone = old
            .iter()
            .zip(&observed)
            .map(|(r, o)| and_not(r, o))
            .collect();
        views.push(ViewChanges {
            name: dataset.views[index].name.clone(),
            index,
            old,
            observed,
            new,
            gone,
        });
        cameras.push(camera);
        on_view(index + 1, total);
    }
    let truth: Vec<Option<Vec<Option<Mask>>>> = truth;
    let mut steps = vec![score(
        "raw",
        &views.iter().map(|v| v.new.clone()).collect::<Vec<_>>(),
        &truth,
    )];

    // Tolerance band: a new blob lying wholly within `band_px` of the same class's old damage
    // is old damage seen a little shifted.
    for v in &mut views {
        v.new = v
            .new
            .iter()
            .zip(&v.old)
            .map(|(n, r)| drop_slivers(n, &dilate(r, config.band_px)))
            .collect();
    }
    steps.push(score(
        "band",
        &views.iter().map(|v| v.new.clone()).collect::<Vec<_>>(),
        &truth,
    ));

    for v in &mut views {
        v.new = v
            .new
            .iter()
            .map(|m| drop_small(m, config.min_area_px))
            .collect();
    }
    steps.push(score(
        "area",
        &views.iter().map(|v| v.new.clone()).collect::<Vec<_>>(),
        &truth,
    ));

    if let Some(earlier) = earlier.filter(|e| !e.is_empty()) {
        for ((view, camera), depth) in views.iter_mut().zip(&cameras).zip(&depths) {
            earlier.drop_old(camera, depth, &mut view.new);
        }
        steps.push(score(
            "earlier",
            &views.iter().map(|v| v.new.clone()).collect::<Vec<_>>(),
            &truth,
        ));
    }

    if config.vote {
        vote(twin, &cameras, &mut views, &settings);
        steps.push(score(
            "vote",
            &views.iter().map(|v| v.new.clone()).collect::<Vec<_>>(),
            &truth,
        ));
    }
    Ok(Detection { views, steps })
}

/// Keeps the candidate pixels whose Gaussians the views agree on: per class, each Gaussian's
/// blending weight over candidate pixels against its weight over every pixel, summed over the
/// views; the Gaussians where candidates hold the majority are rendered back into each view,
/// and candidates they do not cover are dropped.
fn vote(twin: &Splats, cameras: &[Camera], views: &mut [ViewChanges], settings: &RenderSettings) {
    let classes = DamageClass::ALL.len();
    let channels = classes + 1;
    let mut lift = WeightLift::new(twin, channels, *settings);
    let mut candidate = vec![[0.0f64; 3]; twin.len()];
    let mut total = vec![0.0f64; twin.len()];
    for (camera, view) in cameras.iter().zip(views.iter()) {
        let new = &view.new;
        let weights = lift.view(camera, |p, c| {
            if c == classes {
                1.0
            } else {
                f32::from(new[c].data[p] != 0)
            }
        });
        for g in 0..twin.len() {
            let w = &weights[g * channels..(g + 1) * channels];
            for c in 0..classes {
                candidate[g][c] += f64::from(w[c]);
            }
            total[g] += f64::from(w[classes]);
        }
    }
    // The voted Gaussians as label channels: probability 1 where voted, 0 elsewhere.
    let mut probe = twin.clone();
    probe.label_channels = classes;
    probe.raw_labels = (0..twin.len())
        .flat_map(|g| (0..classes).map(move |c| (g, c)))
        .map(|(g, c)| {
            if total[g] > 0.0 && candidate[g][c] > 0.5 * total[g] {
                30.0
            } else {
                -30.0
            }
        })
        .collect();
    for (camera, view) in cameras.iter().zip(views.iter_mut()) {
        let out = render(&probe, camera, settings);
        for (c, mask) in view.new.iter_mut().enumerate() {
            for (p, v) in mask.data.iter_mut().enumerate() {
                // Covered by voted Gaussians (a quarter of the pixel's weight or more).
                if *v != 0 && !(out.labels[p * classes + c] > 0.25) {
                    *v = 0;
                }
            }
        }
    }
}

/// The change map of one view: the photo dimmed, old damage still seen in its class colour, new
/// damage in the new-damage colour, damage no longer seen in cyan.
pub fn change_picture(
    view: &ViewChanges,
    photo: &crate::scene::RgbImage,
    colours: &[[u8; 3]; 3],
    new_colour: [u8; 3],
) -> crate::scene::RgbImage {
    const GONE: [u8; 3] = [0, 200, 255];
    let mut image = photo.clone();
    let unit = |c: [u8; 3]| c.map(|v| f32::from(v) / 255.0);
    for (p, rgb) in image.data.chunks_exact_mut(3).enumerate() {
        rgb.iter_mut().for_each(|v| *v *= 0.3);
        for (c, colour) in colours.iter().enumerate() {
            if view.new[c].data[p] != 0 {
                rgb.copy_from_slice(&unit(new_colour));
            } else if view.gone[c].data[p] != 0 {
                rgb.copy_from_slice(&unit(GONE));
            } else if view.old[c].data[p] != 0 && view.observed[c].data[p] != 0 {
                rgb.copy_from_slice(&unit(*colour));
            }
        }
    }
    image
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(w: u32, h: u32, cells: &[(u32, u32)]) -> Mask {
        let mut m = Mask::empty(w, h);
        for &(x, y) in cells {
            m.data[(y * w + x) as usize] = 1;
        }
        m
    }

    #[test]
    fn band_and_area_drop_thin_edges_and_specks() {
        // Old damage: a vertical line at x = 5. Observed: the line shifted by one pixel (a
        // misregistration), a speck, a real new 4×4 block, and growth from the old line's lower
        // end: a horizontal run from x = 4 to x = 11 on row 13 (its first pixels in the band).
        let old = mask(20, 15, &(0..12).map(|y| (5, y)).collect::<Vec<_>>());
        let mut cells: Vec<(u32, u32)> = (0..12).map(|y| (6, y)).collect();
        cells.push((15, 1));
        for y in 6..10 {
            for x in 12..16 {
                cells.push((x, y));
            }
        }
        let growth: Vec<(u32, u32)> = (4..12).map(|x| (x, 13)).collect();
        cells.extend(&growth);
        let observed = mask(20, 15, &cells);
        let raw = and_not(&observed, &old);
        assert_eq!(raw.count(), 12 + 1 + 16 + 8);
        let banded = drop_slivers(&raw, &dilate(&old, 2));
        assert_eq!(
            banded.count(),
            1 + 16 + 8,
            "the shifted line lies within the band and goes; the growth reaching out of it stays whole"
        );
        for &(x, y) in &growth {
            assert_eq!(
                banded.data[(y * 20 + x) as usize],
                1,
                "growth pixel ({x}, {y})"
            );
        }
        let cleaned = drop_small(&banded, 4);
        assert_eq!(
            cleaned.count(),
            16 + 8,
            "the speck is dropped, the block stays"
        );
    }
}
