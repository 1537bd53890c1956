//! The segmentation study: what a real segmenter's masks are worth, alone and through the twin.
//! `crack_sets` scores the model against the truth masks of the crack photos in `../shared/data`
//! (crackforest, the tunnel and welding samples) at each scale and tile size, and times it on 1
//! and 2 threads; `demo` segments the demo building's photos with it (no truth masks used),
//! trains a label-mode twin on those masks and scores the twin's crack masks against the clean
//! truth beside the model's own. `rows` holds the shared types; `chart` draws them.

pub mod chart;
pub mod crack_sets;
pub mod demo;
pub mod rows;

pub use rows::{CrackSetRow, DemoResult, SegmentStudy, SegmentStudyConfig, SpeedRow};
