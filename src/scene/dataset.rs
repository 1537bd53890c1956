//! A posed image dataset, whatever format it came from: the views (image file, pinhole camera at
//! the stored resolution, how to undistort), the initial points, where masks live, and the
//! problems found while reading. Opening reads only metadata; pixels load per view, at a scale.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use serde::Serialize;

use crate::scene::DamageClass;
use crate::scene::mask_source::MaskSource;
use crate::scene::view_cache::ViewCache;
use crate::scene::{Camera, Mask, PointCloud, RgbImage};

/// Which reader recognised the dataset.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum DatasetFormat {
    /// A COLMAP sparse model (`sparse/0/` or `sparse/`), binary `.bin` files.
    ColmapBinary,
    /// A COLMAP sparse model, text `.txt` files.
    ColmapText,
    /// `transforms.json` (nerfstudio / instant-ngp) or NeRF-synthetic `transforms_{train,test}.json`.
    Transforms,
}

/// Which role a view has in the dataset as written (NeRF-synthetic has explicit splits; other
/// formats leave the choice to the held-out rule, e.g. every 8th image).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    Train,
    Test,
    Unspecified,
}

/// Radial-tangential lens distortion (OpenCV's k1 k2 p1 p2, COLMAP's SIMPLE_RADIAL and RADIAL
/// being special cases) of a view whose image must be undistorted to `View::camera` on load.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Distortion {
    /// Intrinsics of the distorted image as stored.
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub k1: f32,
    pub k2: f32,
    pub p1: f32,
    pub p2: f32,
}

/// One posed image.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// The image file name without extension: masks are found by this stem.
    pub name: String,
    pub image_path: PathBuf,
    /// Pinhole camera at the stored image resolution (after undistortion, when `distortion` is set).
    pub camera: Camera,
    /// Set when the stored image is distorted and must be remapped to `camera` on load.
    pub distortion: Option<Distortion>,
    pub split: Split,
    /// The image's ignore mask named by the dataset itself (nerfstudio's per-frame `mask_path`),
    /// used instead of COLMAP's `masks/<image file name>.png`.
    pub ignore_mask: Option<PathBuf>,
}

/// An opened dataset: metadata only.
#[derive(Clone, Debug)]
pub struct Dataset {
    pub root: PathBuf,
    pub format: DatasetFormat,
    /// Registered views (with a pose and an existing image file), in name order.
    pub views: Vec<View>,
    /// Image files found on disk (registered or not).
    pub image_files: usize,
    /// Distinct cameras (intrinsics entries) in the model.
    pub camera_count: usize,
    /// Camera model names as the format spells them (e.g. `PINHOLE`, `OPENCV`), with counts.
    pub camera_models: BTreeMap<String, usize>,
    /// Initial points (SfM points, or `ply_file_path` of nerfstudio), if the dataset has any.
    pub points: Option<PointCloud>,
    /// Where the views' damage and ignore masks come from (`masks/` beside the images, when
    /// present: `MaskFolder`).
    pub masks: Option<Arc<dyn MaskSource>>,
    /// Mask files found per class.
    pub mask_counts: BTreeMap<DamageClass, usize>,
    /// Colour RGBA images are composited on (NeRF-synthetic: white or black).
    pub background: [f32; 3],
    /// Problems that did not stop reading (missing files, unregistered images).
    pub warnings: Vec<String>,
    /// Views loaded before, kept for loading again (`keep_loaded_views`); None: every load
    /// reads the files.
    pub view_cache: Option<Arc<ViewCache>>,
}

/// One view's pixels at a chosen scale, with its camera scaled to match.
#[derive(Clone, Debug)]
pub struct LoadedView {
    pub name: String,
    pub camera: Camera,
    pub image: RgbImage,
    /// Damage masks present for this view (nearest-neighbour resized to the image).
    pub masks: BTreeMap<DamageClass, Mask>,
    /// The ignore mask (1 = use, 0 = ignore), when the image has one (`masks/<file>.png`).
    pub ignore: Option<Mask>,
}

impl Dataset {
    /// From now on each view is decoded and resized once per scale and kept (`ViewCache`):
    /// `load_view`, and `load_view_masks` of the dataset's own masks, return the kept copy.
    /// For a job that reads the same views many times (the survey update); the views stay in
    /// memory until the last clone of this dataset is dropped. The views (`views`) must not
    /// change while they are kept.
    pub fn keep_loaded_views(&mut self) {
        self.view_cache
            .get_or_insert_with(|| Arc::new(ViewCache::new()));
    }

    /// Views with an ignore mask (nerfstudio's `mask_path`, or COLMAP's
    /// `masks/<image file name>.png`).
    pub fn ignore_mask_count(&self) -> usize {
        self.views
            .iter()
            .filter(|v| self.has_ignore_mask(v))
            .count()
    }

    /// Whether view `view` has an ignore mask: the file the dataset names for it, else one in
    /// the mask source (COLMAP's `masks/<image file name>.png`).
    pub fn has_ignore_mask(&self, view: &View) -> bool {
        view.ignore_mask.is_some() || self.masks.as_ref().is_some_and(|m| m.has_ignore_mask(view))
    }

    /// The index of the view named `name`: its full name (`images/0049.jpg`'s stem path) or the
    /// last part of it (`0049`).
    pub fn view_index(&self, name: &str) -> Option<usize> {
        self.views
            .iter()
            .position(|v| v.name == name || v.name.ends_with(&format!("/{name}")))
    }

    /// A few view names, for an error message saying what names look like.
    pub fn example_view_names(&self) -> String {
        let names: Vec<&str> = self.views.iter().take(4).map(|v| v.name.as_str()).collect();
        names.join(", ")
    }
}
