//! A segmenter's per-class probabilities beside the masks: `probabilities/<class>/<stem>.png`,
//! 8-bit grey, 0 → 0 and 255 → 1, at the photo's stored size (written by `segment`, so a
//! threshold can change without running the model again). Read here for display.

use std::path::{Path, PathBuf};

use crate::scene::load::decode;
use crate::scene::{DamageClass, SceneError};

/// A probability per pixel, 0..=255 for 0..=1, row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProbabilityMap {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

/// Where view `stem`'s probabilities of `class` are in the dataset at `root`.
pub fn probability_path(root: &Path, class: DamageClass, stem: &str) -> PathBuf {
    root.join("probabilities")
        .join(class.id())
        .join(format!("{stem}.png"))
}

/// Reads a probability PNG (16-bit files keep their top 8 bits); refused, naming both files,
/// when its size is not its image's stored size `stored`.
pub fn read_probability_map(
    path: &Path,
    image_path: &Path,
    stored: (u32, u32),
) -> Result<ProbabilityMap, SceneError> {
    let grey = decode(path)?.to_luma8();
    if grey.dimensions() != stored {
        return Err(SceneError::invalid(
            path,
            format!(
                "probabilities are {}×{} but the image {} is {}×{}",
                grey.width(),
                grey.height(),
                image_path.display(),
                stored.0,
                stored.1
            ),
        ));
    }
    Ok(ProbabilityMap {
        width: grey.width(),
        height: grey.height(),
        data: grey.into_raw(),
    })
}
