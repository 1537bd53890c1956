//! Reports: charts and tables of measured results, as files. Presentation only: every figure
//! arrives computed; nothing here renders a model or trains.

pub mod chart_range;
pub mod georeference;
pub mod inspection;
pub mod project_runs;
pub mod tradeoff_chart;
pub mod training_chart;

use std::path::{Path, PathBuf};

/// A chart that could not be drawn or written.
#[derive(Debug, thiserror::Error)]
#[error("drawing {}: {message}", path.display())]
pub struct ChartError {
    pub path: PathBuf,
    pub message: String,
}

impl ChartError {
    pub(crate) fn new(path: &Path, error: impl std::fmt::Display) -> ChartError {
        ChartError {
            path: path.to_path_buf(),
            message: error.to_string(),
        }
    }
}
