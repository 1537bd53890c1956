//! Damage: classes and colours, the supervision modes (overlay targets, label channels), reading
//! rendered damage back and scoring it, and the mask-noise study. Uses the engine; contains no
//! rendering or optimisation of its own.

pub mod assess;
pub mod bench;
pub mod display;
pub mod evaluate;
pub mod hierarchy;
pub mod hulls;
pub mod layer;
pub mod lift;
pub mod mode;
pub mod overlay;
pub mod palette;
pub mod reference;
pub mod refine;
pub mod select;
pub mod setup;

// The classes live beneath `scene` (mask folders and PLY properties are named by them).
pub use crate::scene::damage_class::{DamageClass, NEW_DAMAGE_COLOUR};
pub use mode::TrainMode;
pub use palette::Palette;
pub mod study;
