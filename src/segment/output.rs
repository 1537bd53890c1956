//! What segmentation writes beside a dataset's photos, in the dataset's convention: the mask
//! `masks/<class>/<photo>.png` (0/255, read by every mask reader through `scene::MaskFolder`) and
//! the probability `probabilities/<class>/<photo>.png` (8-bit, `round(p · 255)`), both written
//! atomically. A mask is the probability's 8-bit value at or above the threshold, so
//! re-thresholding the stored probabilities (`masks_from_probabilities`) gives exactly the masks a
//! new run at that threshold would.

use std::path::{Path, PathBuf};

use crate::scene::load::{load_image, save_grey_png, save_mask_png};
use crate::scene::probabilities::probability_path;
use crate::scene::{DamageClass, Mask};
use crate::segment::{ProbabilityMap, SegmentError};

/// `<root>/masks/<class>/<name>.png`.
pub fn mask_path(root: &Path, class: DamageClass, name: &str) -> PathBuf {
    root.join("masks")
        .join(class.id())
        .join(format!("{name}.png"))
}

/// A probability as stored: 8 bits.
pub fn quantise(probability: f32) -> u8 {
    (probability.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Whether a stored probability is damage at `threshold`.
pub fn is_damage(stored: u8, threshold: f32) -> bool {
    f32::from(stored) / 255.0 >= threshold
}

/// The mask of stored probabilities at `threshold`.
pub fn threshold_mask(width: u32, height: u32, stored: &[u8], threshold: f32) -> Mask {
    Mask {
        width,
        height,
        data: stored
            .iter()
            .map(|&v| u8::from(is_damage(v, threshold)))
            .collect(),
    }
}

/// A threshold in [0, 1].
pub fn check_threshold(threshold: f32) -> Result<(), SegmentError> {
    if (0.0..=1.0).contains(&threshold) {
        Ok(())
    } else {
        Err(SegmentError::Settings(format!(
            "threshold {threshold} is outside [0, 1]"
        )))
    }
}

/// Writes photo `name`'s probability and mask of `class` under `root`; returns the mask.
pub fn write_class(
    root: &Path,
    class: DamageClass,
    name: &str,
    map: &ProbabilityMap,
    threshold: f32,
) -> Result<Mask, SegmentError> {
    let stored: Vec<u8> = map.data.iter().map(|&p| quantise(p)).collect();
    let mask = threshold_mask(map.width, map.height, &stored, threshold);
    for path in [
        mask_path(root, class, name),
        probability_path(root, class, name),
    ] {
        if let Some(folder) = path.parent() {
            std::fs::create_dir_all(folder).map_err(|e| crate::scene::SceneError::io(folder, e))?;
        }
    }
    save_grey_png(
        &probability_path(root, class, name),
        map.width,
        map.height,
        stored,
    )?;
    save_mask_png(&mask_path(root, class, name), &mask)?;
    Ok(mask)
}

/// The first of photos `names`' mask or probability files of `classes` under `root` that is
/// already there.
pub fn first_existing(root: &Path, classes: &[DamageClass], names: &[String]) -> Option<PathBuf> {
    names.iter().find_map(|name| {
        classes.iter().find_map(|&class| {
            [
                mask_path(root, class, name),
                probability_path(root, class, name),
            ]
            .into_iter()
            .find(|p| p.exists())
        })
    })
}

/// Rewrites photo `name`'s mask of `class` from its stored probability at `threshold`; returns
/// the mask. A missing or unreadable probability is an error naming it.
pub fn mask_from_probability(
    root: &Path,
    class: DamageClass,
    name: &str,
    threshold: f32,
) -> Result<Mask, SegmentError> {
    let path = probability_path(root, class, name);
    let image = load_image(&path)?;
    let stored: Vec<u8> = image
        .data
        .chunks_exact(3)
        .map(|rgb| (rgb[0] * 255.0).round() as u8)
        .collect();
    let mask = threshold_mask(image.width, image.height, &stored, threshold);
    save_mask_png(&mask_path(root, class, name), &mask)?;
    Ok(mask)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_probabilities_rethreshold_to_the_masks_a_run_writes() {
        let dir = tempfile::tempdir().unwrap();
        let map = ProbabilityMap {
            width: 4,
            height: 1,
            data: vec![0.1, 0.49, 0.5, 0.97],
        };
        let written = write_class(dir.path(), DamageClass::Crack, "a", &map, 0.5).unwrap();
        assert_eq!(written.data, vec![0, 0, 1, 1]);
        let again = mask_from_probability(dir.path(), DamageClass::Crack, "a", 0.5).unwrap();
        assert_eq!(again, written);
        let lower = mask_from_probability(dir.path(), DamageClass::Crack, "a", 0.09).unwrap();
        assert_eq!(lower.data, vec![1, 1, 1, 1]);
        let read =
            crate::scene::masks::read_binary_mask(&mask_path(dir.path(), DamageClass::Crack, "a"))
                .unwrap();
        assert_eq!(read, lower);
        assert!(first_existing(dir.path(), &[DamageClass::Crack], &["a".into()]).is_some());
        assert!(first_existing(dir.path(), &[DamageClass::Spalling], &["a".into()]).is_none());
    }

    #[test]
    fn a_missing_probability_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let err = mask_from_probability(dir.path(), DamageClass::Crack, "b", 0.5).unwrap_err();
        assert!(err.to_string().contains("probabilities"), "{err}");
    }
}
