//! The demo building: a deterministic procedural damaged RC frame, photographed by a simulated
//! drone at two survey dates, written as COLMAP datasets with exact masks, depth and labels.
//! Must not depend on the trainer; same seed, same bytes.

pub mod area;
pub mod bridge;
pub mod bridge_damage;
pub mod building;
pub mod corrupt;
pub mod cracks;
pub mod damage;
pub mod demo;
pub mod drone;
pub mod generate;
pub mod geometry;
pub mod joint;
pub mod lighting;
pub mod materials;
pub mod noise;
pub mod params;
pub mod quantities;
pub mod render;
pub mod stamp;
pub mod write;

pub use generate::{World, generate, view_name};
pub use params::{Structure, Survey2Frame, SurveyOutput, SynthError, SynthOutput, SynthParams};
