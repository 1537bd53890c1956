//! Saving and exporting from the viewer: the twin project (`twin.ron` + model PLY) and the
//! standard 3DGS PLY, each written atomically (temporary file, fsync, rename) so that a crash
//! never leaves a half-written file under the real name. Formats themselves live in `scene`.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::app::settings::Settings;
use crate::damage::DamageClass;
use crate::scene::ImageScale;
use crate::scene::ply;
use crate::scene::project::{ClassStyle, Project, ProjectSettings, Survey};
use crate::splats::Splats;

/// File name of the model inside a saved project.
pub const MODEL_FILE: &str = "model.ply";

/// A sibling temporary path in the same folder (rename is atomic only within one file system).
fn temporary_beside(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Writes through `write` into a temporary file, syncs it and renames it over `path`.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&Path) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let tmp = temporary_beside(path);
    let result = write(&tmp).and_then(|()| {
        fs::File::open(&tmp)
            .and_then(|f| f.sync_all())
            .with_context(|| format!("syncing {}", tmp.display()))?;
        fs::rename(&tmp, path)
            .with_context(|| format!("renaming {} to {}", tmp.display(), path.display()))
    });
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Exports the model as a standard 3DGS PLY (damage-twin's extra properties appended).
pub fn export_ply(path: &Path, splats: &Splats) -> anyhow::Result<()> {
    write_atomically(path, |tmp| {
        ply::write_splats(tmp, splats).with_context(|| format!("writing {}", path.display()))
    })
}

/// Saves the twin into `dir`: `model.ply` and `twin.ron` (one survey: the open dataset), the
/// project file last so that an interrupted save never names a model that is not there.
pub fn save_project(
    dir: &Path,
    dataset_root: Option<&Path>,
    splats: &Splats,
    settings: &Settings,
) -> anyhow::Result<()> {
    fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let project_file = dir.join(crate::scene::project::PROJECT_FILE);
    // Keep what an existing project knows (other surveys, metrics); replace the model.
    let mut project = if project_file.exists() {
        Project::load(&project_file)
            .with_context(|| format!("reading {}", project_file.display()))?
    } else {
        Project::new()
    };
    project.classes = DamageClass::ALL
        .iter()
        .zip(settings.damage.colours)
        .map(|(&class, colour)| ClassStyle { class, colour })
        .collect();
    project.settings = ProjectSettings {
        background: settings.background,
        scale: ImageScale::Factor(settings.training.resolution_factor),
        ..project.settings
    };
    export_ply(&dir.join(MODEL_FILE), splats)?;
    let dataset = dataset_root.map(Path::to_path_buf).unwrap_or_default();
    match project.surveys.iter_mut().find(|s| s.dataset == dataset) {
        Some(survey) => survey.model = Some(PathBuf::from(MODEL_FILE)),
        None => {
            project
                .add_survey(Survey {
                    name: "survey-1".into(),
                    date: today(),
                    dataset,
                    model: Some(PathBuf::from(MODEL_FILE)),
                    metrics: None,
                })
                .with_context(|| format!("adding the survey to {}", project_file.display()))?;
        }
    }
    project
        .save(&project_file)
        .with_context(|| format!("writing {}", project_file.display()))
}

/// Today's date as `YYYY-MM-DD` (UTC), from the system clock.
fn today() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let days = (secs / 86_400) as i64;
    // Civil-from-days (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn today_is_a_date() {
        let t = today();
        assert_eq!(t.len(), 10);
        assert!(t.starts_with("20"), "{t}");
    }
}
