//! Damage: classes and colours, and (later) overlay targets, label channels, selection, hull masks
//! and refinement. Uses the engine; contains no rendering or optimisation of its own.

pub mod classes;

pub use classes::{DamageClass, NEW_DAMAGE_COLOUR};
