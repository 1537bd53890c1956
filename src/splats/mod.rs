//! The Gaussian model as a structure of arrays, its activations and spherical harmonics, and its
//! two file formats (`ply`: 3DGS PLY with the damage extras; `spz`: Niantic's compressed), read
//! and written through `scene`'s file helpers. No rendering, no optimiser state.

pub mod init;
pub mod model;
pub mod ply;
pub mod random;
pub mod selection;
pub mod sh;
pub mod spz;

pub use model::{MAX_LABEL_CHANNELS, SplatMeta, Splats};
