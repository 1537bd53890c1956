//! damage-twin: a digital twin of structural damage built with 3D Gaussian splatting.
//!
//! Modules follow the pipeline (see docs/ARCHITECTURE.md): `scene` reads and writes inputs,
//! `splats` is the model, `raster` renders and differentiates it on the CPU, `gpu` does the same
//! in WGSL, `train` optimises, `damage`/`timeline` use the engine, `studies` measure it, `synth` makes the demo building.

#[cfg(feature = "app")]
pub mod app;
pub mod blocks;
pub mod damage;
pub mod gpu;
pub mod metrics;
pub mod raster;
pub mod report;
pub mod scene;
pub mod segment;
pub mod simd;
pub mod splats;
pub mod studies;
pub mod synth;
pub mod timeline;
pub mod train;
