//! The error every segmentation step returns: always the file (model, photo or mask) and what is
//! wrong with it, on one line.

use std::path::PathBuf;

use crate::scene::SceneError;

#[derive(Debug, thiserror::Error)]
pub enum SegmentError {
    /// The model file cannot be read or is not an ONNX model tract can run.
    #[error("{}: cannot load the ONNX model: {message}", path.display())]
    Model { path: PathBuf, message: String },
    /// The model's inputs or outputs do not fit what segmentation feeds it or reads from it.
    #[error("{}: {message}", path.display())]
    Shape { path: PathBuf, message: String },
    /// Running the model on a photo failed.
    #[error("{}: the model failed on this photo: {message}", path.display())]
    Run { path: PathBuf, message: String },
    /// A mask or probability file is already there and overwriting was not asked for.
    #[error(
        "{}: already exists (masks are not overwritten: pass --overwrite, or move them away)",
        path.display()
    )]
    Exists { path: PathBuf },
    /// Settings that cannot work (a tile smaller than its overlap, a threshold outside [0, 1]).
    #[error("{0}")]
    Settings(String),
    /// Reading a photo or writing a mask.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// Stopped by the caller (the job was cancelled).
    #[error("segmentation cancelled")]
    Cancelled,
}

/// The message on one line (tract's errors can carry a backtrace-like chain over several lines).
pub(crate) fn one_line(message: impl std::fmt::Display) -> String {
    let text = format!("{message:#}");
    if !text.contains(['\n', '\r']) {
        return text;
    }
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}
