//! From a folder of photos to a posed dataset: COLMAP is the structure-from-motion engine (it is
//! driven, never re-implemented), and this module turns its output into a dataset the rest of the
//! project opens, with metres and north from the photos' GPS or from surveyed control points.
//!
//! - `engine`: the engine (COLMAP's CLI, or COLMAP 4 through pycolmap and the shipped script),
//!   finding it, running one of its commands with the log kept and progress read
//!   from its own output, failures reported with the command and its last lines.
//! - `progress`: COLMAP's log lines as progress (stage, done, total).
//! - `pose`: the pipeline (stage, extract, match, map, largest component, dataset, commit).
//! - `draws`: several mapper draws (seeds) on one database, and the one kept: the most photos
//!   among the draws whose camera centres agree with the photos' GPS.
//! - `register`: a later survey's photos registered into a model `pose` kept, its poses fixed.
//! - `workspace`: the photo folder and COLMAP workspace both share (photos, masks, arguments).
//! - `exif`: the photos' focal length and GPS position.
//! - `georef`: the similarity from the SfM frame to a local east-north-up frame in metres.
//! - `control`: surveyed control points (CSV) and the fit to them, with check points.
//!
//! docs/POSE.md has the measurements that chose the engine and its settings.

pub mod control;
pub mod draws;
pub mod engine;
pub mod error;
pub mod exif;
pub mod georef;
pub mod pose;
pub mod progress;
pub mod register;
pub mod workspace;

pub use engine::{Colmap, Engine};
pub use error::SfmError;
pub use georef::{GeorefSource, Georeference};
pub use pose::{Matching, PoseOptions, PoseSummary, pose_photos};
pub use progress::{Progress, Stage};
pub use register::{RegisterSummary, RegistrationResidual, register_photos};
