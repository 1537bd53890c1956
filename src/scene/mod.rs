//! Scene inputs and outputs: cameras, dataset readers (COLMAP, transforms.json), images and masks,
//! PLY, the twin project file. Knows nothing of rendering or training.

pub mod camera;
pub mod dataset;
pub mod error;
pub mod image;
pub mod points;

pub use camera::{Camera, Intrinsics};
pub use dataset::{Dataset, DatasetFormat, Distortion, LoadedView, Split, View};
pub use error::SceneError;
pub use image::{ImageScale, Mask, RgbImage};
pub use points::PointCloud;
