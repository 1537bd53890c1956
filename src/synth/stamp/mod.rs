//! Damage stamped onto a real posed capture, with exact truth (docs/STAMP.md): planes fitted to
//! the capture's sparse points, damage placed on them in 3D at sizes in metres (crack shapes and
//! pixels from real crack photos and their masks, seeded spalls with exposed bars), drawn into
//! every photo that sees it through the camera's lens, and written as a dataset per survey with
//! truth masks and quantities laid out as `synth` writes them.

pub mod decal;
pub mod output;
pub mod params;
pub mod place;
pub mod planes;
pub mod quantities;
pub mod render;
pub mod run;
pub mod scale;
pub mod sources;

pub use params::{StampError, StampParams, parse_classes};
pub use run::{StampSummary, stamp};
