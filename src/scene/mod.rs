//! Scene inputs and outputs: cameras, dataset readers (COLMAP, transforms.json), images and masks,
//! PLY, the twin project file. Knows nothing of rendering or training.

pub mod atomic;
pub mod camera;
pub mod colmap;
pub mod damage_class;
pub mod dataset;
pub mod error;
pub mod files;
pub mod image;
pub mod limits;
pub mod load;
pub mod mask_import;
pub mod mask_source;
pub mod masks;
pub mod open;
pub mod ply;
pub mod points;
pub mod probabilities;
pub mod project;
pub mod run_folder;
pub mod sfm;
pub mod similarity;
pub mod survey_name;
pub mod transforms;
pub mod undistort;
pub mod view_cache;

pub use camera::{Camera, Intrinsics};
pub use damage_class::{DamageClass, NEW_DAMAGE_COLOUR};
pub use dataset::{Dataset, DatasetFormat, Distortion, LoadedView, Split, View};
pub use error::SceneError;
pub use image::{ImageScale, Mask, RgbImage};
pub use mask_source::{InMemoryMasks, MaskFolder, MaskSource};
pub use points::PointCloud;
