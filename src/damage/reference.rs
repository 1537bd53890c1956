//! Reference masks for evaluating rendered damage: a synthetic survey's clean `truth/masks/` when
//! the dataset has one (its `masks/` may be deliberately corrupted), else the dataset's own masks.

use std::path::PathBuf;

use rayon::prelude::*;

use crate::damage::DamageClass;
use crate::damage::evaluate::ReferenceView;
use crate::scene::{Dataset, ImageScale, SceneError};

/// Where reference masks come from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ReferenceSource {
    /// `<dataset>/truth/masks/` (written by `damage-twin synth`).
    Truth(PathBuf),
    /// The dataset's `masks/` folder.
    DatasetMasks(PathBuf),
}

impl ReferenceSource {
    pub fn dir(&self) -> &std::path::Path {
        match self {
            ReferenceSource::Truth(dir) | ReferenceSource::DatasetMasks(dir) => dir,
        }
    }
}

/// The reference folder of `dataset`, or None when it has no masks at all.
pub fn reference_source(dataset: &Dataset) -> Option<ReferenceSource> {
    let truth = dataset.root.join("truth").join("masks");
    if truth.is_dir() {
        return Some(ReferenceSource::Truth(truth));
    }
    dataset
        .masks_dir
        .clone()
        .filter(|d| d.is_dir())
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
            let (camera, mut masks) = dataset.load_view_masks(index, source.dir(), scale)?;
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
