//! The survey timeline: the twin project (a folder with `twin.ron`) and its surveys in date
//! order, each with its dataset, its model (the twin as of that survey) and its metrics. Later
//! surveys are placed in the twin's frame, compared with it and used to update it; an earlier
//! survey's model is never overwritten. Uses `scene` for the file format, `train`/`damage` for
//! the work; must not contain UI.

pub mod add_survey;
pub mod align;
pub mod appearance;
pub mod blocks;
pub mod changes;
pub mod components;
pub mod detect_survey;
pub mod earlier;
pub mod from_photos;
pub mod georeference;
pub mod lock;
pub mod near_floaters;
pub mod project_paths;
pub mod quantities;
pub mod record;
pub mod register_survey;
pub mod seed;
pub mod segment_survey;
pub mod survey;
pub mod twin;
pub mod update;
pub mod update_rates;

pub use twin::{TimelineError, Twin};
