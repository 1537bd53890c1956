//! The mask-noise study's inputs: the training views with their clean masks, and the same masks
//! corrupted at a rate by the study's noise model (`synth::corrupt`).

use crate::damage::DamageClass;
use crate::damage::evaluate::ReferenceView;
use crate::damage::reference::{ReferenceSource, load_reference_views};
use crate::scene::masks::resize_mask_nearest;
use crate::scene::{Dataset, Mask};
use crate::studies::mask_noise::rows::{NoiseModel, StudyConfig};
use crate::synth::corrupt::{corrupt_class_mask, corrupt_mask_by_area, noisy_views};
use crate::train::spec::TrainView;
use crate::train::views::load_views;

/// Clean masks of the training views and what is needed to corrupt them.
pub(crate) struct CleanTraining {
    pub(crate) views: Vec<TrainView>,
    /// Per view, where added blobs may be centred (not sky), when the dataset says.
    building: Vec<Vec<bool>>,
    pub(crate) reference: Vec<ReferenceView>,
}

pub(crate) fn load_clean_training(
    dataset: &Dataset,
    source: &ReferenceSource,
    indices: &[usize],
    config: &StudyConfig,
) -> Result<CleanTraining, String> {
    let scale = config.run.scale;
    let mut views = load_views(dataset, indices, scale, false).map_err(|e| e.to_string())?;
    let reference =
        load_reference_views(dataset, source, indices, scale).map_err(|e| e.to_string())?;
    let mut building = Vec::with_capacity(views.len());
    for (view, reference) in views.iter_mut().zip(&reference) {
        let (w, h) = (view.image.width, view.image.height);
        view.labels = reference
            .reference
            .iter()
            .map(|m| m.clone().unwrap_or_else(|| Mask::empty(w, h)))
            .collect();
        building.push(structure_pixels(dataset, &view.name, w, h));
    }
    Ok(CleanTraining {
        views,
        building,
        reference,
    })
}

/// Pixels showing the structure (not sky), from a synthetic survey's component labels
/// (`truth/components/<view>.png`, sky = 0); every pixel when there are none.
fn structure_pixels(dataset: &Dataset, name: &str, width: u32, height: u32) -> Vec<bool> {
    let path = dataset
        .root
        .join("truth/components")
        .join(format!("{name}.png"));
    let all = || vec![true; width as usize * height as usize];
    let Ok(image) = image::open(&path) else {
        return all();
    };
    let grey = image.to_luma8();
    let ids = Mask {
        width: grey.width(),
        height: grey.height(),
        data: grey.into_raw(),
    };
    resize_mask_nearest(&ids, width, height)
        .data
        .iter()
        .map(|&id| id != 0)
        .collect()
}

/// The training masks at `rate`: which views are noisy, and per view per class the masks.
pub(crate) fn corrupt(
    clean: &CleanTraining,
    noise: NoiseModel,
    rate: f32,
    seed: u64,
) -> (Vec<bool>, Vec<Vec<Mask>>) {
    let noisy = match noise {
        NoiseModel::Area => vec![rate > 0.0; clean.views.len()],
        NoiseModel::Views => noisy_views(clean.views.len(), rate, seed),
    };
    let mut rng = fastrand::Rng::with_seed(seed ^ 0x5EED_0FB1_0B00);
    let masks = clean
        .views
        .iter()
        .zip(&noisy)
        .zip(&clean.building)
        .map(|((view, &is_noisy), building)| {
            let mut masks = view.labels.clone();
            if is_noisy {
                for (class, mask) in DamageClass::ALL.iter().zip(masks.iter_mut()) {
                    let (w, h) = (mask.width as usize, mask.height as usize);
                    match noise {
                        NoiseModel::Area => {
                            corrupt_mask_by_area(&mut mask.data, w, h, building, rate, &mut rng);
                        }
                        NoiseModel::Views => {
                            corrupt_class_mask(*class, &mut mask.data, w, h, building, &mut rng)
                        }
                    }
                }
            }
            masks
        })
        .collect();
    (noisy, masks)
}
