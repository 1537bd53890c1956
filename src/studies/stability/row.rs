//! A row of the stability study: one twin's held-out figures at one setting of one axis. The
//! leaf the runs, the tables and the chart look down to.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// One row of the study.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StabilityRow {
    /// `textureless`, `views`, `pose_noise`, `mask_noise` or `scale`.
    pub axis: String,
    /// The axis's setting: 0/1 (textured/flat colours), training views, degrees of pose noise,
    /// mask corruption rate, or the training image's downscale factor.
    pub value: f64,
    /// Held-out PSNR (dB) and SSIM, against the photos (SSIM absent on rows taken from the
    /// mask-noise study, which does not measure it).
    pub psnr: f64,
    pub ssim: Option<f64>,
    /// Held-out IoU per damage class against the clean masks.
    pub iou: BTreeMap<String, f64>,
    pub gaussians: usize,
    /// Training time, held-out evaluation excluded.
    pub seconds: f64,
    /// Training image size.
    pub width: u32,
    pub height: u32,
}
