//! Optimisation of splats against images: losses with exact gradients, Adam, adaptive density
//! control, and (from the trainer) the steerable training run and its job API.
//! Reads no files and draws nothing: inputs arrive as buffers, results leave as events.

pub mod adam;
pub mod appearance;
pub mod backend_choice;
pub mod compact;
pub mod densify;
pub mod evaluate;
pub mod focus;
pub mod guards;
pub mod history;
pub mod importance;
pub mod job;
pub mod label_loss;
pub mod light_fit;
pub mod loss;
pub mod plateau;
pub mod priority;
pub mod region_runs;
pub mod run;
pub mod scale_cap;
pub mod schedule;
pub mod spec;
pub mod ssim;
pub mod trainer;
pub mod views;
