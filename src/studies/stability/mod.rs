//! The stability study: where the twin holds and where it breaks. Each axis (views, pose noise,
//! scale, texture, mask noise) moves alone from a baseline run, scored on the same held-out
//! views (`row` and `perturb` are the leaves `run`, `suite`, `table` and `chart` look down to).

pub mod chart;
pub mod mask_noise_axis;
pub mod perturb;
pub mod row;
pub mod run;
pub mod suite;
pub mod table;

pub use perturb::{Perturbation, perturb, perturb_pose};
pub use row::StabilityRow;
pub use run::stability_run;
pub use suite::{StabilityConfig, StabilityOutcome, run_stability};
