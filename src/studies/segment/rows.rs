//! The segmentation study's settings and results (JSON as written to docs/figures).

use serde::{Deserialize, Serialize};

/// What the study runs.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SegmentStudyConfig {
    /// crackforest photos scored (its first ones; SOURCE.md's figures use 20).
    pub crackforest_images: usize,
    /// (scale spelling, tile side) pairs scored on every set.
    pub settings: Vec<(String, u32)>,
    pub overlap: u32,
    pub threshold: f32,
    /// Demo building: photo size, views and training iterations of the label-mode twin.
    pub demo_width: u32,
    pub demo_height: u32,
    pub demo_views: usize,
    pub demo_iterations: u32,
}

impl Default for SegmentStudyConfig {
    fn default() -> Self {
        SegmentStudyConfig {
            crackforest_images: 20,
            settings: vec![
                ("1".into(), 512),
                ("1".into(), 256),
                ("0.5".into(), 512),
                ("0.5".into(), 128),
            ],
            overlap: 32,
            threshold: 0.5,
            demo_width: 480,
            demo_height: 270,
            demo_views: 16,
            demo_iterations: 400,
        }
    }
}

/// The model on one set at one setting: per-image means, as SOURCE.md reports.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CrackSetRow {
    pub set: String,
    pub scale: String,
    pub tile: u32,
    pub images: usize,
    pub iou: f64,
    /// Within 2 px.
    pub precision: f64,
    pub recall: f64,
}

/// Speed at scale 1, 512-pixel tiles, on the crackforest photos.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SpeedRow {
    pub threads: usize,
    pub seconds_per_megapixel: f64,
    pub images_per_second: f64,
}

/// The demo building: the model's masks against the clean truth, and the twin trained on them.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct DemoResult {
    pub views: usize,
    pub width: u32,
    pub height: u32,
    pub iterations: u32,
    /// Crack IoU of the model's masks on the training views (pooled over their pixels), and its
    /// per-view mean.
    pub model_iou: f64,
    pub model_iou_per_view_mean: f64,
    pub model_precision: f64,
    pub model_recall: f64,
    /// Crack IoU of the twin's rendered masks on the same training views, pooled.
    pub twin_iou: f64,
    pub twin_precision: f64,
    pub twin_recall: f64,
    /// On the held-out views (no segmented mask of theirs was trained on).
    pub twin_heldout_iou: f64,
    pub model_heldout_iou: f64,
    pub train_seconds: f64,
}

/// Everything the study measured.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SegmentStudy {
    pub config: SegmentStudyConfig,
    pub model: String,
    pub crack_sets: Vec<CrackSetRow>,
    pub speed: Vec<SpeedRow>,
    pub demo: Option<DemoResult>,
}
