//! The mask-noise study: how much segmentation error the twin removes. Trains on masks corrupted
//! at each rate and scores the rendered masks against the clean ones (`rows` holds the shared
//! types; `run` → `fine` → `scores` → `clean` → `rows`, each looking only down that line).

pub mod chart;
mod clean;
mod fine;
pub mod rows;
pub mod run;
mod scores;

pub use rows::{NoiseModel, StudyConfig, StudyEvent, StudyRow, StudyStage};
pub use run::run_study;
