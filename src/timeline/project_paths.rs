//! Where a project's own files live: inside its folder. Every output path `twin.ron` names (a
//! survey's model, metrics, change maps) and every survey folder written is resolved here, and
//! refused when it climbs out of the project (`..`, an absolute path) or passes through a link
//! that leads out. Datasets are inputs and may lie anywhere; they are not resolved here.

use std::path::{Path, PathBuf};

use crate::scene::atomic::write_atomic;
use crate::scene::files::open_regular;
use crate::scene::project::stays_inside;
use crate::timeline::detect_survey::CHANGES_DIR;
use crate::timeline::twin::{HISTORY_FILE, METRICS_FILE, TimelineError, Twin, io_error as io};

impl Twin {
    /// `path` (relative to the project folder, as `twin.ron` stores it) joined to the folder,
    /// when it stays inside: lexically (no `..`, not absolute) and through every link on the way
    /// that exists now. A part that does not exist yet is created inside by whoever writes it.
    pub fn inside(&self, path: &Path) -> Result<PathBuf, TimelineError> {
        let outside = |at: &Path| TimelineError::Outside {
            path: at.to_path_buf(),
            dir: self.dir().to_path_buf(),
        };
        if !stays_inside(path) {
            return Err(outside(path));
        }
        let root = std::fs::canonicalize(self.dir()).map_err(|e| io(self.dir(), e))?;
        let mut at = self.dir().to_path_buf();
        for part in path.components() {
            at.push(part);
            match std::fs::symlink_metadata(&at) {
                Ok(meta) if meta.file_type().is_symlink() => {
                    // A dangling link counts as leading out: where it would create is unknown.
                    match std::fs::canonicalize(&at) {
                        Ok(real) if real.starts_with(&root) => {}
                        _ => return Err(outside(&at)),
                    }
                }
                Ok(_) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => break,
                Err(e) => return Err(io(&at, e)),
            }
        }
        Ok(self.dir().join(path))
    }

    /// The folder of survey `name`'s outputs, `<dir>/surveys/<name>/`, checked to lie inside the
    /// project (`inside`). Only a survey of the project has one: an unknown name is refused
    /// before anything is looked up on disk.
    pub fn survey_dir(&self, name: &str) -> Result<PathBuf, TimelineError> {
        self.inside(&self.survey_relative(name)?)
    }

    /// `file` (a name or a relative path) in survey `name`'s folder, checked like `survey_dir`.
    pub fn survey_file(&self, name: &str, file: &str) -> Result<PathBuf, TimelineError> {
        self.inside(&self.survey_relative(name)?.join(file))
    }

    fn survey_relative(&self, name: &str) -> Result<PathBuf, TimelineError> {
        let survey = &self.project.surveys[self.survey_index(name)?];
        Ok(Path::new(SURVEYS_DIR).join(&survey.name))
    }

    /// Copies survey `name`'s records (metrics, training history, change maps) from `source`,
    /// another project, into this project's folder for that survey and records them here: a
    /// project saved into a new folder ("save as") holds its own files rather than naming the
    /// old project's. Files that are not regular files are skipped. Inside a `commit` they are
    /// staged with the survey's other files.
    pub fn copy_survey_records(&mut self, source: &Twin, name: &str) -> Result<(), TimelineError> {
        let index = self.survey_index(name)?;
        let from = &source.project.surveys[source.survey_index(name)?];
        let mut metrics = None;
        if let Some(file) = &from.metrics {
            copy_file(
                &source.inside(file)?,
                &self.output_path(name, METRICS_FILE)?,
            )?;
            metrics = Some(self.relative(&self.survey_file(name, METRICS_FILE)?));
        }
        let history = source.survey_file(name, HISTORY_FILE)?;
        if history.is_file() {
            copy_file(&history, &self.output_path(name, HISTORY_FILE)?)?;
        }
        let mut changes = None;
        if let Some(old) = &from.changes {
            let old = source.inside(old)?;
            let new = self.output_path(name, CHANGES_DIR)?;
            std::fs::create_dir_all(&new).map_err(|e| io(&new, e))?;
            for entry in std::fs::read_dir(&old).map_err(|e| io(&old, e))? {
                let entry = entry.map_err(|e| io(&old, e))?;
                if entry.file_type().is_ok_and(|t| t.is_file()) {
                    copy_file(&entry.path(), &new.join(entry.file_name()))?;
                }
            }
            changes = Some(self.relative(&self.survey_file(name, CHANGES_DIR)?));
        }
        let survey = &mut self.project.surveys[index];
        survey.metrics = metrics;
        survey.changes = changes;
        Ok(())
    }
}

/// The folder holding one folder per survey.
pub const SURVEYS_DIR: &str = "surveys";

/// Copies a file atomically (the copy is a new file, never a write through a link). The source
/// is opened like any project file (`open_regular`): a FIFO or a device named in `twin.ron` is
/// refused naming it, not read for ever.
fn copy_file(from: &Path, to: &Path) -> Result<(), TimelineError> {
    let mut source = open_regular(from)?;
    write_atomic(to, |w| std::io::copy(&mut source, w).map(drop))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saved_as_elsewhere_a_project_holds_copies_of_its_records() {
        let root = tempfile::tempdir().unwrap();
        let mut source = Twin::create(&root.path().join("old")).unwrap();
        source
            .add_survey("2024", "2024-06-01", &root.path().join("data"))
            .unwrap();
        source
            .save_metrics("2024", &serde_json::json!({"psnr": 30.0}))
            .unwrap();
        source
            .save_history("2024", &crate::train::history::History::default())
            .unwrap();
        let changes = source.survey_file("2024", CHANGES_DIR).unwrap();
        std::fs::create_dir_all(&changes).unwrap();
        std::fs::write(changes.join("view.png"), b"png").unwrap();
        source.project.surveys[0].changes = Some(source.relative(&changes));

        let mut copy = Twin::create(&root.path().join("new")).unwrap();
        copy.project = source.project.clone();
        copy.copy_survey_records(&source, "2024").unwrap();
        let survey = &copy.project.surveys[0];
        assert_eq!(
            survey.metrics.as_deref(),
            Some(Path::new("surveys/2024/metrics.json"))
        );
        assert_eq!(
            survey.changes.as_deref(),
            Some(Path::new("surveys/2024/changes"))
        );
        let new = root.path().join("new/surveys/2024");
        assert_eq!(std::fs::read(new.join("changes/view.png")).unwrap(), b"png");
        assert!(new.join(HISTORY_FILE).is_file());
        assert_eq!(
            copy.load_metrics("2024").unwrap(),
            source.load_metrics("2024").unwrap()
        );
    }
}
