//! Scene inputs and outputs: cameras, dataset readers (COLMAP, transforms.json), images and masks,
//! PLY, the twin project file. Knows nothing of rendering or training.

pub mod camera;

pub use camera::{Camera, Intrinsics};
