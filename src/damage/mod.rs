//! Damage: classes and colours, the supervision modes (overlay targets, label channels), reading
//! rendered damage back and scoring it, measuring it on the surface (`measure`: lengths, widths,
//! areas) and compaction on a dataset. Uses the engine; renders no camera view and optimises
//! nothing of its own (`measure` splats labels straight onto a surface plane).

pub mod assess;
pub mod bake;
pub mod bench;
pub mod compact;
pub mod display;
pub mod evaluate;
pub mod hull_picture;
pub mod layer;
pub mod measure;
pub mod mode;
pub mod overlay;
pub mod palette;
pub mod pick;
pub mod reference;
pub mod refine;
mod refine_config;
mod refine_quality;
mod refine_selection;
pub mod select;
pub mod setup;
pub mod truth_hulls;
pub mod view_damage;

// The classes live beneath `scene` (mask folders and PLY properties are named by them).
pub use crate::scene::damage_class::{DamageClass, NEW_DAMAGE_COLOUR};
pub use mode::TrainMode;
pub use palette::Palette;
