//! Reference masks for evaluating rendered damage: a synthetic survey's clean `truth/masks/` when
//! the dataset has one (its `masks/` may be deliberately corrupted), else the dataset's own masks.

use std::sync::Arc;

use rayon::prelude::*;

use crate::damage::DamageClass;
use crate::damage::evaluate::ReferenceView;
use crate::scene::{Dataset, ImageScale, MaskFolder, MaskSource, SceneError};

/// Where reference masks come from.
#[derive(Clone, Debug)]
pub enum ReferenceSource {
    /// `<dataset>/truth/masks/` (written by `damage-twin synth`).
    Truth(MaskFolder),
    /// The dataset's own masks (`Dataset::masks`).
    DatasetMasks(Arc<dyn MaskSource>),
}

impl ReferenceSource {
    pub fn masks(&self) -> &dyn MaskSource {
        match self {
            ReferenceSource::Truth(folder) => folder,
            ReferenceSource::DatasetMasks(source) => source.as_ref(),
        }
    }
}

/// The reference masks of `dataset`, or None when it has no masks at all.
pub fn reference_source(dataset: &Dataset) -> Option<ReferenceSource> {
    let truth = MaskFolder::truth(&dataset.root);
    if truth.is_available() {
        return Some(ReferenceSource::Truth(truth));
    }
    dataset
        .masks
        .clone()
        .filter(|m| m.is_available())
        .map(ReferenceSource::DatasetMasks)
}

/// Cameras (at `scale`) and reference masks of the views `indices`, loaded in parallel: per
/// class (`DamageClass::ALL` order) a mask, `None` for a class without a mask file for the view.
pub fn load_reference_views(
    dataset: &Dataset,
    source: &ReferenceSource,
    indices: &[usize],
    scale: ImageScale,
) -> Result<Vec<ReferenceView>, SceneError> {
    indices
        .par_iter()
        .map(|&index| {
            let (camera, mut masks) = dataset.load_view_masks(index, source.masks(), scale)?;
            Ok(ReferenceView {
                name: dataset.views[index].name.clone(),
                camera,
                used: dataset.load_view_ignore(index, scale)?,
                reference: DamageClass::ALL
                    .iter()
                    .map(|class| masks.remove(class))
                    .collect(),
            })
        })
        .collect()
}
