//! The benchmark on real photos (issue 42 §2–§3): on a capture with damage stamped onto its
//! photos (`synth::stamp`, exact truth), what the demo building gets — the crack model's masks
//! and their per-view errors against the truth, a label-mode twin on the truth masks (IoU per
//! class), its fine-tune at the photos' resolution (refinement gain), a twin on the model's
//! masks (the share of the model's errors it corrects), change detection against survey 2 and
//! the measured crack length and spalled area against the stamped quantities. `run` drives it,
//! `pixels` scores masks (per view, corrections), `quantities` compares the measurement with the
//! truth, `rows` holds the JSON, `chart` draws it.

pub mod chart;
pub mod pixels;
pub mod quantities;
pub mod rows;
pub mod run;

pub use rows::{RealStudy, RealStudyConfig};
pub use run::{Segmenter, run_real};
