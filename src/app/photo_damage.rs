//! The damage a snapped photo is shown with, so a user sees what the segmenter (or the imported
//! annotations) said before training on it: each class's mask, or its probability when the
//! segmenter wrote `probabilities/<class>/<stem>.png`, tinted over the photo in the class colour.

use serde::{Deserialize, Serialize};

use crate::scene::probabilities::{probability_path, read_probability_map};
use crate::scene::{DamageClass, Dataset, LoadedView, RgbImage};

/// What a snapped photo shows of its damage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum PhotoDamage {
    /// The photo as it is.
    #[default]
    Off,
    /// The view's masks (`masks/<class>/`), as training reads them.
    Masks,
    /// The segmenter's probabilities where it wrote them, else the masks.
    Probabilities,
}

/// How strongly a certain damage pixel is tinted (the photo stays visible under it).
const TINT: f32 = 0.6;

/// Tints `view`'s photo (as loaded, at its scale) with its damage in `colours` (sRGB per class in
/// `DamageClass::ALL` order). Probabilities are read at the stored size and resized to the
/// photo's; a view with lens distortion shows its masks (they are undistorted on load, the
/// probability files are not). Returns what could not be read, for the log.
pub fn tint_damage(
    dataset: &Dataset,
    index: usize,
    view: &mut LoadedView,
    mode: PhotoDamage,
    colours: [[u8; 3]; 3],
) -> Vec<String> {
    let mut problems = Vec::new();
    if mode == PhotoDamage::Off {
        return problems;
    }
    let Some(info) = dataset.views.get(index) else {
        return problems;
    };
    let (w, h) = (view.image.width, view.image.height);
    for class in DamageClass::ALL {
        let path = probability_path(&dataset.root, class, &info.name);
        let probabilities =
            (mode == PhotoDamage::Probabilities && info.distortion.is_none() && path.is_file())
                .then(|| {
                    let stored = crate::scene::files::image_size(&info.image_path)?;
                    read_probability_map(&path, &info.image_path, stored)
                });
        let weights: Option<Vec<f32>> = match probabilities {
            Some(Ok(map)) => image::GrayImage::from_raw(map.width, map.height, map.data).map(|g| {
                image::imageops::resize(&g, w, h, image::imageops::FilterType::Triangle)
                    .into_raw()
                    .into_iter()
                    .map(|p| f32::from(p) / 255.0)
                    .collect()
            }),
            Some(Err(e)) => {
                problems.push(e.to_string());
                None
            }
            None => None,
        };
        let weights = weights.or_else(|| {
            view.masks.get(&class).map(|m| {
                m.data
                    .iter()
                    .map(|&v| f32::from(u8::from(v != 0)))
                    .collect()
            })
        });
        if let Some(weights) = weights {
            tint(&mut view.image, &weights, colours[class.channel()]);
        }
    }
    problems
}

/// Blends `colour` over `image` by `weights` (one per pixel, 0..=1) times `TINT`.
fn tint(image: &mut RgbImage, weights: &[f32], colour: [u8; 3]) {
    let colour = colour.map(|c| f32::from(c) / 255.0);
    for (rgb, &w) in image.data.chunks_exact_mut(3).zip(weights) {
        let a = TINT * w.clamp(0.0, 1.0);
        for (v, c) in rgb.iter_mut().zip(colour) {
            *v = *v * (1.0 - a) + c * a;
        }
    }
}
