//! Scene inputs and outputs: cameras, dataset readers (COLMAP, transforms.json), images and masks,
//! PLY, the twin project file. Knows nothing of rendering or training.

pub mod camera;
pub mod error;
pub mod points;

pub use camera::{Camera, Intrinsics};
pub use error::SceneError;
pub use points::PointCloud;
