//! The hierarchy study: full high-resolution training against a coarse twin, coarse + fine-tune
//! and coarse + retrain, each timed and scored at high resolution on the held-out views
//! (`config` and `rows` are the leaves `run` and `table` look down to).

pub mod config;
pub mod rows;
pub mod run;
pub mod table;

pub use config::{HierarchyConfig, Method, default_config};
pub use rows::{HierarchyOutcome, HierarchyRow};
pub use run::{hierarchy_job, run_hierarchy};
