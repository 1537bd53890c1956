//! The error of the photo-to-dataset pipeline: one line, naming the file, the command or the
//! package to install.

use std::path::PathBuf;

use crate::scene::SceneError;

#[derive(Debug, thiserror::Error)]
pub enum SfmError {
    #[error(
        "`{program}` was not found on PATH: install COLMAP (Debian/Ubuntu: `apt-get install \
         colmap`), or set DAMAGE_TWIN_COLMAP to its path"
    )]
    EngineMissing { program: String },
    #[error(
        "the pycolmap engine (COLMAP 4) is not available: {why}; install it with `pip install \
         pycolmap`, or choose Debian's COLMAP with `--engine colmap`"
    )]
    PycolmapMissing { why: String },
    #[error(
        "COLMAP failed ({status}) running `{command}`; its last lines: {tail} (full log: {})",
        log.display()
    )]
    EngineFailed {
        command: String,
        status: String,
        tail: String,
        log: PathBuf,
    },
    /// The run was cancelled (`PoseOptions::cancel`): COLMAP stopped, nothing written.
    #[error("cancelled: COLMAP was stopped and nothing was written")]
    Cancelled,
    /// The inputs cannot make a dataset (too few photos, no overlap, a bad control point).
    #[error("{}: {message}", path.display())]
    Input { path: PathBuf, message: String },
    #[error(transparent)]
    Scene(#[from] SceneError),
}

impl SfmError {
    pub fn input(path: impl Into<PathBuf>, message: impl Into<String>) -> SfmError {
        SfmError::Input {
            path: path.into(),
            message: message.into(),
        }
    }
}
