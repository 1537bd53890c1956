//! PLY files: the header and row reader every PLY reader here shares (`header`) and coloured
//! point clouds. The Gaussian-splat layout built on them is `splats::ply`, beside the model it
//! stores.

pub(crate) mod header;
mod points;

pub use points::{read_point_cloud, read_point_cloud_skipping, write_point_cloud};
