//! Damage: classes and colours, the supervision modes (overlay targets, label channels), reading
//! rendered damage back and scoring it, measuring it on the surface (`measure`: lengths, widths,
//! areas), and the mask-noise study. Uses the engine; renders no camera view and optimises
//! nothing of its own (`measure` splats labels straight onto a surface plane).

pub mod assess;
pub mod bake;
pub mod bench;
pub mod display;
pub mod evaluate;
pub mod hierarchy;
pub mod hull_picture;
pub mod hulls;
pub mod layer;
pub mod measure;
pub mod mode;
pub mod overlay;
pub mod palette;
pub mod pick;
pub mod reference;
pub mod refine;
mod refine_quality;
mod refine_selection;
pub mod select;
pub mod setup;
pub mod stability;

// The classes live beneath `scene` (mask folders and PLY properties are named by them).
pub use crate::scene::damage_class::{DamageClass, NEW_DAMAGE_COLOUR};
pub use mode::TrainMode;
pub use palette::Palette;
pub mod study;
pub mod study_fine;
pub(crate) mod study_scores;
