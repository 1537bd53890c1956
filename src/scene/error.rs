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
            message: one_line(message.into()),
        }
    }

    pub fn unsupported(path: impl AsRef<Path>, message: impl Into<String>) -> SceneError {
        SceneError::Unsupported {
            path: path.as_ref().to_path_buf(),
            message: one_line(message.into()),
        }
    }
}

/// The message on one line: other crates' error texts can hold line breaks (zune-jpeg's end in
/// one, found by `tests/fuzz_readers.rs`), and every error is printed as one line.
fn one_line(message: String) -> String {
    if !message.contains(['\n', '\r']) {
        return message;
    }
    message.split_whitespace().collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_are_kept_on_one_line() {
        let err = SceneError::invalid(
            "a.jpg",
            "cannot decode image: Not enough bytes, expected 64 but found 59\n",
        );
        assert_eq!(
            err.to_string(),
            "a.jpg: cannot decode image: Not enough bytes, expected 64 but found 59"
        );
        let err = SceneError::unsupported("b.ply", "two\r\nlines");
        assert_eq!(err.to_string(), "b.ply: unsupported: two lines");
        // A message without breaks keeps its spacing.
        assert!(
            SceneError::invalid("c", "a  b")
                .to_string()
                .ends_with("a  b")
        );
    }
}
