//! `Twin`: an opened twin project folder. Opens and saves `twin.ron` (atomically, through
//! `scene::project`, one writer at a time through `timeline::lock`), adds surveys with dataset
//! paths stored relative to the folder, and writes each survey's model and metrics under
//! `surveys/<name>/`, kept inside the folder by `project_paths`. The app and the CLI both go
//! through here; neither writes project files itself.

use std::path::{Component, Path, PathBuf};

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::scene::SceneError;
use crate::scene::atomic::write_atomic;
use crate::scene::files::{is_present, read_regular};
use crate::scene::limits::MAX_PROJECT_JSON_BYTES;
use crate::scene::project::{PROJECT_FILE, Project, Survey, SurveyError};
use crate::scene::survey_name::{same_survey_name, survey_name_from};
use crate::splats::Splats;
use crate::splats::ply;
use crate::timeline::lock::{LockError, ProjectLock, Writer};
use crate::timeline::record::SurveyRecord;
use crate::timeline::twin::staging::{Staged, recover_if_idle};
use crate::train::history::History;

/// File names inside a survey's folder.
pub const MODEL_FILE: &str = "model.ply";
pub const METRICS_FILE: &str = "metrics.json";
/// The training history that made the survey's model (loss, held-out PSNR, Gaussians against
/// wall time), for the report's charts.
pub const HISTORY_FILE: &str = "history.json";

#[derive(Debug, thiserror::Error)]
pub enum TimelineError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    // `problem` is no `#[source]`: it is already in the message, and anyhow's chain would print it
    // a second time.
    #[error("{}: {problem}", file.display())]
    Survey { file: PathBuf, problem: SurveyError },
    #[error("{}: no survey named `{}` (surveys: {known})", file.display(), name.escape_debug())]
    NoSurvey {
        file: PathBuf,
        name: String,
        known: String,
    },
    #[error("{}: the project has no survey yet", file.display())]
    Empty { file: PathBuf },
    #[error("{}: a twin project already exists there", file.display())]
    Exists { file: PathBuf },
    #[error(transparent)]
    Lock(#[from] LockError),
    /// Segmenting a survey's photos (`twin add-survey --segment`).
    #[error(transparent)]
    Segment(#[from] crate::segment::SegmentError),
    /// Registering a survey's photos by COLMAP (`twin add-survey --photos --align colmap`).
    #[error(transparent)]
    Sfm(#[from] crate::scene::sfm::SfmError),
    #[error(
        "{}: changed by another command since it was read; open the project again and redo the change",
        file.display()
    )]
    Changed { file: PathBuf },
    #[error("{}: {message}", path.display())]
    Io { path: PathBuf, message: String },
    /// A path the project names, or a link on it, leads out of the project folder.
    #[error("{}: lies outside the project folder {}; a project's files stay inside it", path.display(), dir.display())]
    Outside { path: PathBuf, dir: PathBuf },
}

/// A twin project opened from (or created in) a folder.
#[derive(Clone, Debug)]
pub struct Twin {
    dir: PathBuf,
    pub project: Project,
    /// The project as `twin.ron` held it when last read or written here (None: not saved yet), to
    /// refuse a save over another writer's change.
    base: Option<Project>,
    /// How this process's writes are named to other writers, and how long they wait.
    writer: Writer,
    /// The survey folders the commit in progress writes (`staging`); empty outside one.
    staged: Staged,
    /// What this process cleaned up after a killed command when it opened the project.
    recovered: Vec<PathBuf>,
}

/// Two twins are the same project in the same folder, whoever writes them.
impl PartialEq for Twin {
    fn eq(&self, other: &Twin) -> bool {
        self.dir == other.dir && self.project == other.project
    }
}

impl Twin {
    /// A new, empty project in `dir` (created when missing); refuses a folder that already holds
    /// a project. Nothing is written until `save`.
    pub fn create(dir: &Path) -> Result<Twin, TimelineError> {
        let file = dir.join(PROJECT_FILE);
        if file.exists() {
            return Err(TimelineError::Exists { file });
        }
        std::fs::create_dir_all(dir).map_err(|e| io_error(dir, e))?;
        Ok(Twin {
            dir: dir.to_path_buf(),
            project: Project::new(),
            base: None,
            writer: Writer::default(),
            staged: Staged::default(),
            recovered: Vec::new(),
        })
    }

    /// Opens a project: its folder or its `twin.ron`.
    pub fn open(path: &Path) -> Result<Twin, TimelineError> {
        let (dir, file) = if path.is_dir() {
            (path.to_path_buf(), path.join(PROJECT_FILE))
        } else {
            let dir = match path.parent() {
                Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
                _ => PathBuf::from("."),
            };
            (dir, path.to_path_buf())
        };
        // Before reading: a commit killed half-way is rolled back or its leftovers removed.
        let recovered = recover_if_idle(&dir);
        let project = Project::load(&file)?;
        Ok(Twin {
            dir,
            base: Some(project.clone()),
            project,
            writer: Writer::default(),
            staged: Staged::default(),
            recovered,
        })
    }

    /// Opens the project in `dir`, or starts a new one there when it holds none.
    pub fn open_or_create(dir: &Path) -> Result<Twin, TimelineError> {
        if dir.join(PROJECT_FILE).is_file() {
            Twin::open(dir)
        } else {
            Twin::create(dir)
        }
    }

    /// The project folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The project file, `<dir>/twin.ron`.
    pub fn file(&self) -> PathBuf {
        self.dir.join(PROJECT_FILE)
    }

    /// This project's writes named `writer` to other writers (and waiting as long as it says).
    pub fn with_writer(self, writer: Writer) -> Twin {
        Twin { writer, ..self }
    }

    /// Writes `twin.ron` atomically as this project holds it, under the project's lock. Refuses
    /// when another command changed the file since it was read here (or made a project where this
    /// one is new): a whole-file save never overwrites a record it has not seen. A change to
    /// part of a project is a `commit`.
    pub fn save(&mut self) -> Result<(), TimelineError> {
        let _lock = ProjectLock::acquire(&self.dir, &self.writer)?;
        self.recover_locked();
        let file = self.file();
        let unchanged = match &self.base {
            Some(base) => &Project::load(&file)? == base,
            None => !file.exists(),
        };
        if !unchanged {
            return Err(match self.base {
                Some(_) => TimelineError::Changed { file },
                None => TimelineError::Exists { file },
            });
        }
        self.write_project()
    }

    /// Changes the project as its one writer: under the project's lock, reads `twin.ron` again as
    /// other writers left it, applies `change` to that (writing its own survey's files and
    /// editing only its own records), writes `twin.ron` and keeps the result here. A long job
    /// commits only when it ends, so a survey added or a scale set while it ran survives. A new
    /// project (`create`) is refused when one appeared in its folder meanwhile. When `change`
    /// fails, `twin.ron` and this project stay as they were.
    ///
    /// All or nothing: the survey files `change` writes go into a staging folder per survey,
    /// put in place with `twin.ron` at the end (`staging`); a kill at any moment leaves the
    /// project as it was or as committed, and the next command cleans up (and says so).
    pub fn commit<T>(
        &mut self,
        change: impl FnOnce(&mut Twin) -> Result<T, TimelineError>,
    ) -> Result<T, TimelineError> {
        let _lock = ProjectLock::acquire(&self.dir, &self.writer)?;
        self.recover_locked();
        let file = self.file();
        let mut current = self.clone();
        if self.base.is_some() {
            current.project = Project::load(&file)?;
        } else if file.exists() {
            return Err(TimelineError::Exists { file });
        }
        current.staged.committing = true;
        let result = change(&mut current)?;
        current.write_commit()?;
        *self = current;
        Ok(result)
    }

    /// What this process cleaned up after a killed command when it opened the project (the
    /// CLI and the viewer tell the user).
    pub fn recovered(&self) -> &[PathBuf] {
        &self.recovered
    }

    /// Writes `twin.ron`; the caller holds the lock.
    fn write_project(&mut self) -> Result<(), TimelineError> {
        self.project.save(&self.file())?;
        self.base = Some(self.project.clone());
        Ok(())
    }

    /// An input path from the project (a dataset) made usable: relative paths join the project
    /// folder. The project's own files are resolved by `inside`, which keeps them there.
    pub fn resolve(&self, path: &Path) -> PathBuf {
        if path.is_absolute() {
            path.to_path_buf()
        } else {
            self.dir.join(path)
        }
    }

    /// How `path` is stored in `twin.ron`: relative to the project folder when both are on the
    /// same root, so the folder can move with its datasets; absolute otherwise.
    pub fn relative(&self, path: &Path) -> PathBuf {
        let (Ok(target), Ok(base)) = (absolute(path), absolute(&self.dir)) else {
            return path.to_path_buf();
        };
        relative_path(&target, &base).unwrap_or(target)
    }

    /// Appends a survey of `dataset` (not older than the latest survey; name unique).
    pub fn add_survey(
        &mut self,
        name: &str,
        date: &str,
        dataset: &Path,
    ) -> Result<usize, TimelineError> {
        let survey = Survey {
            name: name.to_string(),
            date: date.to_string(),
            dataset: self.relative(dataset),
            model: None,
            metrics: None,
            ..Default::default()
        };
        self.project
            .add_survey(survey)
            .map_err(|problem| TimelineError::Survey {
                file: self.file(),
                problem,
            })
    }

    /// Index of the survey named `name`.
    pub fn survey_index(&self, name: &str) -> Result<usize, TimelineError> {
        self.project
            .surveys
            .iter()
            .position(|s| s.name == name)
            .ok_or_else(|| TimelineError::NoSurvey {
                file: self.file(),
                name: name.to_string(),
                known: self
                    .project
                    .surveys
                    .iter()
                    .map(|s| s.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }

    pub fn survey(&self, name: &str) -> Result<&Survey, TimelineError> {
        Ok(&self.project.surveys[self.survey_index(name)?])
    }

    /// The latest survey (the one the twin shows by default).
    pub fn latest(&self) -> Result<&Survey, TimelineError> {
        self.project
            .surveys
            .last()
            .ok_or_else(|| TimelineError::Empty { file: self.file() })
    }

    /// The survey whose dataset is `dataset` (compared as resolved, absolute paths).
    pub fn survey_of_dataset(&self, dataset: &Path) -> Option<&Survey> {
        let wanted = absolute(dataset).ok()?;
        self.project.surveys.iter().find(|s| {
            !s.dataset.as_os_str().is_empty()
                && absolute(&self.resolve(&s.dataset)).ok().as_ref() == Some(&wanted)
        })
    }

    /// A survey's dataset folder, resolved.
    pub fn dataset_path(&self, name: &str) -> Result<PathBuf, TimelineError> {
        Ok(self.resolve(&self.survey(name)?.dataset))
    }

    /// A survey's model file, resolved inside the project (None before one was saved).
    pub fn model_path(&self, name: &str) -> Result<Option<PathBuf>, TimelineError> {
        self.survey(name)?
            .model
            .as_ref()
            .map(|m| self.inside(m))
            .transpose()
    }

    /// Reads a survey's model.
    pub fn load_model(&self, name: &str) -> Result<Option<Splats>, TimelineError> {
        match self.model_path(name)? {
            Some(path) => Ok(Some(ply::read_splats(&path)?)),
            None => Ok(None),
        }
    }

    /// Writes `splats` as survey `name`'s model (`surveys/<name>/model.ply`; inside a `commit`
    /// staged with the survey's other files, otherwise atomically on its own) and records it in
    /// the project. Only that survey's file is written: every other survey's model stays as it is.
    pub fn save_model(&mut self, name: &str, splats: &Splats) -> Result<PathBuf, TimelineError> {
        let index = self.survey_index(name)?;
        let written = self.output_path(name, MODEL_FILE)?;
        ply::write_splats(&written, splats)?;
        let path = self.survey_file(name, MODEL_FILE)?;
        self.project.surveys[index].model = Some(self.relative(&path));
        Ok(path)
    }

    /// Writes survey `name`'s metrics as pretty JSON (`surveys/<name>/metrics.json`, written as
    /// `save_model` writes) and records the file in the project.
    pub fn save_metrics(
        &mut self,
        name: &str,
        metrics: &impl Serialize,
    ) -> Result<PathBuf, TimelineError> {
        let index = self.survey_index(name)?;
        let path = self.write_survey_json(name, METRICS_FILE, metrics)?;
        self.project.surveys[index].metrics = Some(self.relative(&path));
        Ok(path)
    }

    /// Survey `name`'s metrics, where recorded (a file of no known shape reads as
    /// `SurveyRecord::Other`).
    pub fn load_metrics(&self, name: &str) -> Result<Option<SurveyRecord>, TimelineError> {
        let index = self.survey_index(name)?;
        match &self.project.surveys[index].metrics {
            Some(file) => read_json(&self.inside(file)?).map(Some),
            None => Ok(None),
        }
    }

    /// Writes the training history that made survey `name`'s model
    /// (`surveys/<name>/history.json`, written as `save_model` writes).
    pub fn save_history(
        &mut self,
        name: &str,
        history: &History,
    ) -> Result<PathBuf, TimelineError> {
        self.write_survey_json(name, HISTORY_FILE, history)
    }

    /// The training history of survey `name`'s model, where one was kept.
    pub fn load_history(&self, name: &str) -> Result<Option<History>, TimelineError> {
        let path = self.survey_file(name, HISTORY_FILE)?;
        // Only nothing there is "no history": a folder or a pipe in its place is refused.
        if !is_present(&path) {
            return Ok(None);
        }
        read_json(&path).map(Some)
    }

    pub(crate) fn write_survey_json(
        &mut self,
        name: &str,
        file: &str,
        value: &impl Serialize,
    ) -> Result<PathBuf, TimelineError> {
        let written = self.output_path(name, file)?;
        let path = self.survey_file(name, file)?;
        let text = serde_json::to_string_pretty(value).map_err(|e| TimelineError::Io {
            path: path.clone(),
            message: format!("cannot serialise: {e}"),
        })?;
        write_atomic(&written, |w| std::io::Write::write_all(w, text.as_bytes()))?;
        Ok(path)
    }

    /// Saves the model the viewer shows as the model of the survey of `dataset` (a bare model,
    /// `None`, is a survey without a dataset), adding that survey when the project has none for
    /// it: named after the dataset folder, dated today (or the latest survey's date when that is
    /// later). Writes the model; `twin.ron` is the caller's `commit` to write, after it, so an
    /// interrupted save never names a model that is not there. Returns the survey's name.
    pub fn save_survey_model(
        &mut self,
        dataset: Option<&Path>,
        splats: &Splats,
    ) -> Result<String, TimelineError> {
        let existing = match dataset {
            Some(root) => self.survey_of_dataset(root).map(|s| s.name.clone()),
            None => self
                .project
                .surveys
                .iter()
                .find(|s| s.dataset.as_os_str().is_empty())
                .map(|s| s.name.clone()),
        };
        let name = match existing {
            Some(name) => name,
            None => {
                let base = dataset
                    .and_then(|d| d.file_name())
                    .map(|n| survey_name_from(&n.to_string_lossy()))
                    .unwrap_or_else(|| "survey".into());
                let name = self.unused_name(&base);
                let date = self.next_survey_date();
                let stored = dataset.map(|d| self.relative(d)).unwrap_or_default();
                self.project
                    .add_survey(Survey {
                        name: name.clone(),
                        date,
                        dataset: stored,
                        model: None,
                        metrics: None,
                        ..Default::default()
                    })
                    .map_err(|problem| TimelineError::Survey {
                        file: self.file(),
                        problem,
                    })?;
                name
            }
        };
        self.save_model(&name, splats)?;
        Ok(name)
    }

    /// The date a survey added now takes unless told: today, or the latest survey's date when
    /// that is later (a survey is never dated before the latest).
    pub fn next_survey_date(&self) -> String {
        let today = today();
        match self.project.surveys.last() {
            Some(latest) if latest.date > today => latest.date.clone(),
            _ => today,
        }
    }

    /// A survey name not yet used (compared without case): `base`, else `base-2`, `base-3`, …
    pub fn unused_name(&self, base: &str) -> String {
        let taken = |n: &str| {
            self.project
                .surveys
                .iter()
                .any(|s| same_survey_name(&s.name, n))
        };
        if !taken(base) {
            return base.to_string();
        }
        (2..)
            .map(|i| format!("{base}-{i}"))
            .find(|n| !taken(n))
            .unwrap_or_else(|| base.to_string())
    }
}

/// A JSON file of the project, read whole like any hostile input (`scene::files::read_regular`:
/// a FIFO, a device or a folder is refused at once, a file over `MAX_PROJECT_JSON_BYTES` before
/// it is read); a file that does not parse names itself.
pub(crate) fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T, TimelineError> {
    let bytes = read_regular(path, MAX_PROJECT_JSON_BYTES)?;
    serde_json::from_slice(&bytes).map_err(|e| TimelineError::Io {
        path: path.to_path_buf(),
        message: format!("not valid JSON here: {e}"),
    })
}

pub(crate) fn io_error(path: &Path, e: std::io::Error) -> TimelineError {
    TimelineError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// `path` made absolute against the current folder and cleaned of `.` and `..` (lexically, so
/// that a folder that does not exist yet still has a place).
/// Whether `a` and `b` name the same folder (compared as absolute, cleaned paths).
pub fn same_folder(a: &Path, b: &Path) -> bool {
    match (absolute(a), absolute(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}

fn absolute(path: &Path) -> std::io::Result<PathBuf> {
    let joined = std::path::absolute(path)?;
    let mut out = PathBuf::new();
    for part in joined.components() {
        match part {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            other => out.push(other),
        }
    }
    Ok(out)
}

/// `target` relative to `base` (both absolute and clean), or None when they share no root.
fn relative_path(target: &Path, base: &Path) -> Option<PathBuf> {
    let t: Vec<Component> = target.components().collect();
    let b: Vec<Component> = base.components().collect();
    if t.first() != b.first() {
        return None;
    }
    let common = t.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut out = PathBuf::new();
    for _ in common..b.len() {
        out.push("..");
    }
    for part in &t[common..] {
        out.push(part);
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    Some(out)
}

/// Today's date as `YYYY-MM-DD` (UTC), from the system clock: the default survey date.
pub fn today() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    civil_date((secs / 86_400) as i64)
}

/// The proleptic Gregorian date of a day count since 1970-01-01 (Howard Hinnant's
/// civil-from-days).
pub(crate) fn civil_date(days: i64) -> String {
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

mod staging;
pub use staging::cleanup_message;
#[cfg(test)]
mod tests;
