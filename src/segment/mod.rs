//! Damage masks from the photos themselves: an ONNX segmentation model (run by tract, pure Rust)
//! over a dataset's photos, in overlapping tiles at a chosen scale, written in the dataset's
//! convention (`masks/<class>/<photo>.png`) with the 8-bit probabilities beside them
//! (`probabilities/<class>/<photo>.png`) so a threshold can change without running the model
//! again. Sits between `damage` and `timeline`: the timeline's `add-survey --segment` calls it,
//! and it runs as a `train::job::Job` like every long step. docs/DAMAGE.md has the measured
//! behaviour of the shared crack model.

pub mod error;
pub mod model;
pub mod output;
pub mod photo;
pub mod preprocess;
pub mod run;
pub mod tiles;

pub use error::SegmentError;
pub use model::SegmentModel;
pub use photo::{PhotoSettings, ProbabilityMap, photo_probabilities};
pub use preprocess::{Activation, ChannelOrder, Preprocess};
pub use run::{
    DEFAULT_THRESHOLD, Photo, SegmentSettings, SegmentSummary, dataset_photos,
    masks_from_probabilities, parse_channel_classes, segment_job, segment_photos,
};
pub use tiles::Tiling;
