//! The error every `scene` reader and writer returns: always the file, always what is wrong.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file exists but its content is not what the format allows.
    #[error("{}: {message}", path.display())]
    Invalid { path: PathBuf, message: String },
    /// Valid input that damage-twin does not handle (e.g. a fisheye camera model).
    #[error("{}: unsupported: {message}", path.display())]
    Unsupported { path: PathBuf, message: String },
}

impl SceneError {
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> SceneError {
        SceneError::Io {
            path: path.as_ref().to_path_buf(),
            source,
        }
    }

    pub fn invalid(path: impl AsRef<Path>, message: impl Into<String>) -> SceneError {
        SceneError::Invalid {
            path: path.as_ref().to_path_buf(),
            message: message.into(),
        }
    }

    pub fn unsupported(path: impl AsRef<Path>, message: impl Into<String>) -> SceneError {
        SceneError::Unsupported {
            path: path.as_ref().to_path_buf(),
            message: message.into(),
        }
    }
}
