//! What a path the user dropped or picked is: a twin project, a model or a dataset. Saving and
//! exporting go through `timeline` and `scene`, which write atomically.

use std::path::{Path, PathBuf};

/// What a path the user dropped or picked is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum OpenTarget {
    /// A project file (`twin.ron`).
    Project(PathBuf),
    /// A 3DGS model.
    Ply(PathBuf),
    /// A dataset folder (or a file inside one, e.g. `transforms.json`).
    Dataset(PathBuf),
}

/// Classifies a path: `twin.ron` or a folder holding one is a project, `.ply` a model, anything
/// else a dataset.
pub fn classify(path: &Path) -> OpenTarget {
    let project_file = crate::scene::project::PROJECT_FILE;
    if path.is_dir() && path.join(project_file).is_file() {
        return OpenTarget::Project(path.join(project_file));
    }
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
    {
        Some(e) if e == "ron" => OpenTarget::Project(path.to_path_buf()),
        Some(e) if e == "ply" => OpenTarget::Ply(path.to_path_buf()),
        _ => OpenTarget::Dataset(path.to_path_buf()),
    }
}
