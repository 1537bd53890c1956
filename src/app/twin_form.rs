//! The "New twin from photos…" dialog's fields as data: the folder of photos (picked or typed),
//! where the posed dataset and the twin project go (filled beside the photos when the folder is
//! chosen), the first survey's name and date, and whether the viewer trains the twin once it is
//! posed. `request` turns them into the library's `TwinFromPhotos`; the checks and the work are
//! `timeline::from_photos`'s, the same COLMAP run as `damage-twin pose`.

use std::path::{Path, PathBuf};

use crate::scene::sfm::pose::PoseOptions;
use crate::scene::survey_name::survey_name_from;
use crate::timeline::from_photos::TwinFromPhotos;
use crate::timeline::lock::Writer;

/// The dialog's fields.
#[derive(Clone, Debug, PartialEq)]
pub struct NewTwinForm {
    /// The folder of photos, as typed or picked.
    pub photos: String,
    /// The dataset COLMAP's poses are written as (must not exist, or be empty).
    pub dataset: String,
    /// The twin project's folder (must not hold a project).
    pub project: String,
    pub survey: String,
    /// YYYY-MM-DD.
    pub date: String,
    /// Train the twin in the viewer once the project is made.
    pub train: bool,
    /// Why the last try made no twin (shown until the fields change or the next try).
    pub error: Option<String>,
}

impl Default for NewTwinForm {
    fn default() -> Self {
        NewTwinForm {
            photos: String::new(),
            dataset: String::new(),
            project: String::new(),
            survey: String::new(),
            date: crate::timeline::twin::today(),
            train: true,
            error: None,
        }
    }
}

impl NewTwinForm {
    /// `folder` as the photos; empty fields are filled from it: the dataset `<folder>-posed`
    /// and the project `<folder>-twin` beside it, the survey named after it.
    pub fn choose_photos(&mut self, folder: &Path) {
        self.photos = folder.display().to_string();
        let Some(base) = folder.file_name().map(|b| b.to_string_lossy().into_owned()) else {
            return;
        };
        let beside = |suffix: &str| folder.with_file_name(format!("{base}-{suffix}"));
        if self.dataset.trim().is_empty() {
            self.dataset = beside("posed").display().to_string();
        }
        if self.project.trim().is_empty() {
            self.project = beside("twin").display().to_string();
        }
        if self.survey.trim().is_empty() {
            self.survey = survey_name_from(&base);
        }
    }

    /// The same fields, ignoring the error line.
    pub fn same_inputs(&self, other: &NewTwinForm) -> bool {
        NewTwinForm {
            error: None,
            ..self.clone()
        } == NewTwinForm {
            error: None,
            ..other.clone()
        }
    }

    /// The twin the fields describe, or why they do not describe one yet.
    pub fn request(&self, writer: Writer) -> Result<TwinFromPhotos, String> {
        let path = |text: &str, what: &str| {
            let text = text.trim();
            match text.is_empty() {
                true => Err(format!("choose {what}")),
                false => Ok(PathBuf::from(text)),
            }
        };
        Ok(TwinFromPhotos {
            photos: path(&self.photos, "the folder of photos")?,
            dataset: path(&self.dataset, "where the posed dataset goes")?,
            project: path(&self.project, "the twin project's folder")?,
            survey: self.survey.trim().to_string(),
            date: self.date.trim().to_string(),
            pose: PoseOptions::default(),
            writer,
        })
    }
}
