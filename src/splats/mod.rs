//! The Gaussian model as a structure of arrays, its activations and spherical harmonics.
//! Pure data and maths: no I/O (PLY lives in `scene`), no rendering, no optimiser state.

pub mod init;
pub mod model;
pub mod random;
pub mod selection;
pub mod sh;

pub use model::{MAX_LABEL_CHANNELS, SplatMeta, Splats};
