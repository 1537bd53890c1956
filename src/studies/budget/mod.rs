//! The Gaussian-budget study: a full run against `train --budget` at fractions of its count and
//! compaction of its model, in held-out PSNR, Gaussians, bytes and seconds (`rows` is the leaf
//! `run` and `chart` look down to).

pub mod chart;
pub mod rows;
pub mod run;

pub use rows::{BudgetFile, BudgetRow, SceneRun};
pub use run::{BudgetConfig, BudgetOutcome, budget_job, run_budget};
