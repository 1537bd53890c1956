//! The model against the truth masks of the crack photos in the shared data (crackforest's
//! first photos, the ipcshm tunnel and welding samples): per-image IoU and precision / recall
//! within 2 px, averaged per set as SOURCE.md does, at each (scale, tile) setting; seconds per
//! megapixel on 1 and 2 threads; and overlays (truth green, model red, both yellow) to look at.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;

use crate::metrics::{MaskAgreement, NearAgreement};
use crate::scene::load::{load_image, save_png};
use crate::scene::masks::read_binary_mask;
use crate::scene::{ImageScale, Mask, RgbImage, SceneError};
use crate::segment::{
    PhotoSettings, Preprocess, SegmentError, SegmentModel, Tiling, photo_probabilities,
};
use crate::studies::segment::rows::{CrackSetRow, SegmentStudyConfig, SpeedRow};

/// Distance within which a crack pixel counts as found (SOURCE.md's "within 2 px").
const NEAR_PIXELS: usize = 2;

/// One photo with its truth mask.
#[derive(Clone, Debug)]
pub struct CrackImage {
    pub set: &'static str,
    pub photo: PathBuf,
    pub truth: PathBuf,
}

/// The crack photos under `data` (`../shared/data`): crackforest's first `crackforest`, then the
/// tunnel and welding samples; a set that is not there is left out.
pub fn crack_images(data: &Path, crackforest: usize) -> Vec<CrackImage> {
    let mut images = Vec::new();
    for i in 1..=crackforest {
        let photo = data.join(format!("crackforest/image/{i:03}.jpg"));
        let truth = data.join(format!("crackforest/masks/{i:03}.png"));
        if photo.is_file() && truth.is_file() {
            images.push(CrackImage {
                set: "crackforest",
                photo,
                truth,
            });
        }
    }
    for set in ["tunnel", "welding"] {
        for i in 1..=6 {
            let folder = data.join("ipcshm_tunnel_welding_crack_samples").join(set);
            let photo = folder.join(format!("{i}.png"));
            let truth = folder.join(format!("{i}_m.png"));
            if photo.is_file() && truth.is_file() {
                images.push(CrackImage { set, photo, truth });
            }
        }
    }
    images
}

/// The photo settings of one (scale, tile) pair.
pub fn photo_settings(scale: &str, tile: u32, overlap: u32) -> Result<PhotoSettings, SegmentError> {
    let scale = ImageScale::parse(scale)
        .ok_or_else(|| SegmentError::Settings(format!("unknown scale {scale:?}")))?;
    Ok(PhotoSettings {
        preprocess: Preprocess::default(),
        scale,
        tiling: Tiling {
            tile,
            overlap: overlap.min(tile / 2 - 1),
            multiple: 16,
        },
    })
}

/// One photo's model mask at `threshold`.
fn model_mask(
    model: &SegmentModel,
    image: &RgbImage,
    photo: &Path,
    settings: &PhotoSettings,
    threshold: f32,
) -> Result<Vec<bool>, SegmentError> {
    let maps = photo_probabilities(model, image, photo, settings)?;
    Ok(maps[0].data.iter().map(|&p| p >= threshold).collect())
}

/// Every set at every setting of `config`; `on_line` hears one line per row.
pub fn score_sets(
    model: &SegmentModel,
    images: &[CrackImage],
    config: &SegmentStudyConfig,
    on_line: &mut dyn FnMut(String),
) -> Result<Vec<CrackSetRow>, SegmentError> {
    let loaded: Vec<(RgbImage, Mask)> = images
        .par_iter()
        .map(|i| Ok((load_image(&i.photo)?, read_binary_mask(&i.truth)?)))
        .collect::<Result<_, SceneError>>()?;
    let mut rows = Vec::new();
    for (scale, tile) in &config.settings {
        let settings = photo_settings(scale, *tile, config.overlap)?;
        let per_image: Vec<(f64, f64, f64)> = images
            .par_iter()
            .zip(&loaded)
            .map(|(image, (photo, truth))| {
                let found = model_mask(model, photo, &image.photo, &settings, config.threshold)?;
                Ok(image_scores(&found, truth))
            })
            .collect::<Result<_, SegmentError>>()?;
        for set in ["crackforest", "tunnel", "welding"] {
            let of_set: Vec<&(f64, f64, f64)> = images
                .iter()
                .zip(&per_image)
                .filter(|(i, _)| i.set == set)
                .map(|(_, s)| s)
                .collect();
            if of_set.is_empty() {
                continue;
            }
            let n = of_set.len() as f64;
            let row = CrackSetRow {
                set: set.into(),
                scale: scale.clone(),
                tile: *tile,
                images: of_set.len(),
                iou: of_set.iter().map(|s| s.0).sum::<f64>() / n,
                precision: of_set.iter().map(|s| s.1).sum::<f64>() / n,
                recall: of_set.iter().map(|s| s.2).sum::<f64>() / n,
            };
            on_line(format!(
                "{set} at scale {scale}, tile {tile}: IoU {:.3}, precision {:.3}, recall {:.3} \
                 (within 2 px, {} images)",
                row.iou, row.precision, row.recall, row.images
            ));
            rows.push(row);
        }
    }
    Ok(rows)
}

/// IoU and precision / recall within 2 px of one photo, as SOURCE.md counts them.
fn image_scores(found: &[bool], truth: &Mask) -> (f64, f64, f64) {
    let truth_bits: Vec<bool> = truth.iter_bool().collect();
    let mut agreement = MaskAgreement::default();
    agreement.accumulate(found.iter().copied(), truth_bits.iter().copied());
    let near = NearAgreement::measure(
        found,
        &truth_bits,
        truth.width as usize,
        truth.height as usize,
        NEAR_PIXELS,
    );
    // SOURCE.md counts an image with nothing marked as precision 0 (not 1: no undefined ratio
    // lifts the mean).
    let precision = if near.predicted == 0 {
        0.0
    } else {
        near.precision()
    };
    (agreement.iou(), precision, near.recall())
}

/// Seconds per megapixel and images per second over `images` at scale 1, 512-pixel tiles, on
/// each thread count (after one photo to build the model's plan, which is not timed).
pub fn speed(
    model: &SegmentModel,
    images: &[CrackImage],
    threads: &[usize],
) -> Result<Vec<SpeedRow>, SegmentError> {
    let settings = photo_settings("1", 512, 32)?;
    let loaded: Vec<RgbImage> = images
        .iter()
        .map(|i| load_image(&i.photo))
        .collect::<Result<_, _>>()?;
    if let (Some(first), Some(image)) = (images.first(), loaded.first()) {
        photo_probabilities(model, image, &first.photo, &settings)?;
    }
    let megapixels: f64 = loaded.iter().map(|i| i.pixel_count() as f64).sum::<f64>() / 1e6;
    let mut rows = Vec::new();
    for &n in threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map_err(|e| SegmentError::Settings(format!("{n} worker threads: {e}")))?;
        let started = Instant::now();
        pool.install(|| {
            images.par_iter().zip(&loaded).try_for_each(|(i, image)| {
                photo_probabilities(model, image, &i.photo, &settings).map(|_| ())
            })
        })?;
        let seconds = started.elapsed().as_secs_f64();
        rows.push(SpeedRow {
            threads: n,
            seconds_per_megapixel: seconds / megapixels.max(1e-12),
            images_per_second: images.len() as f64 / seconds.max(1e-9),
        });
    }
    Ok(rows)
}

/// Writes `path`: the photo dimmed, truth-only pixels green, model-only red, both yellow.
pub fn write_overlay(
    path: &Path,
    image: &RgbImage,
    found: &[bool],
    truth: &[bool],
) -> Result<(), SceneError> {
    let mut out = image.clone();
    for (i, px) in out.data.chunks_exact_mut(3).enumerate() {
        let colour = match (found[i], truth[i]) {
            (true, true) => Some([1.0, 0.9, 0.0]),
            (true, false) => Some([1.0, 0.1, 0.1]),
            (false, true) => Some([0.1, 0.9, 0.2]),
            (false, false) => None,
        };
        match colour {
            Some(c) => px.copy_from_slice(&c),
            None => px.iter_mut().for_each(|v| *v *= 0.6),
        }
    }
    save_png(path, &out)
}

/// Overlays of the first photo of each set at scale 1, 512-pixel tiles, into `dir`.
pub fn write_set_overlays(
    model: &SegmentModel,
    images: &[CrackImage],
    dir: &Path,
    threshold: f32,
) -> Result<Vec<PathBuf>, SegmentError> {
    let settings = photo_settings("1", 512, 32)?;
    let mut written = Vec::new();
    for set in ["crackforest", "tunnel", "welding"] {
        let Some(first) = images.iter().find(|i| i.set == set) else {
            continue;
        };
        let image = load_image(&first.photo)?;
        let truth = read_binary_mask(&first.truth)?;
        let found = model_mask(model, &image, &first.photo, &settings, threshold)?;
        let truth: Vec<bool> = truth.iter_bool().collect();
        let path = dir.join(format!("segment-overlay-{set}.png"));
        write_overlay(&path, &image, &found, &truth)?;
        written.push(path);
    }
    Ok(written)
}
