//! A later survey that arrives as photos, registered by COLMAP into an earlier survey's model
//! (`scene::sfm::register`) with the old poses held: its dataset shares that survey's frame, so
//! the survey takes that survey's alignment to the twin. Two steps, like segmenting a survey: the
//! long COLMAP run writes the new dataset outside the project lock (`register_survey_photos`),
//! then `add_placed_survey(…, AlignMode::Colmap)` adds the survey in a `commit`, keeping only
//! the registered new photos as its views and the registration's residual as its record
//! (`surveys/<name>/registration.json`, read by `twin status` and the report).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::scene::open::stem_of;
use crate::scene::project::Survey;
use crate::scene::sfm::pose::PoseOptions;
use crate::scene::sfm::progress::Progress;
use crate::scene::sfm::register::{DATABASE_FILE, RegisterSummary, register_photos};
use crate::timeline::twin::{TimelineError, Twin, read_json, same_folder};

/// A registered survey's record in its folder.
pub const REGISTRATION_FILE: &str = "registration.json";

/// What `twin status` and the report say of a survey registered by COLMAP.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurveyRegistration {
    /// The survey whose model the photos were registered into.
    pub reference_survey: String,
    pub registration: RegisterSummary,
}

impl Twin {
    /// The survey later photos are registered into: the latest whose dataset keeps a COLMAP
    /// workspace (`damage-twin pose` wrote it, or an earlier registration, which holds every
    /// photo registered so far). Returns its name and dataset folder.
    pub fn colmap_reference(&self) -> Result<(String, PathBuf), TimelineError> {
        self.project
            .surveys
            .iter()
            .rev()
            .map(|s| (s.name.clone(), self.resolve(&s.dataset)))
            .find(|(_, dataset)| dataset.join(DATABASE_FILE).is_file())
            .ok_or_else(|| TimelineError::Io {
                path: self.file(),
                message: format!(
                    "no survey's dataset keeps a COLMAP workspace ({DATABASE_FILE}): \
                     `--align colmap` registers into a dataset made by `damage-twin pose`; \
                     use --align joint with a joint model instead"
                ),
            })
    }

    /// Registers the photos in `photos` into `colmap_reference`'s model and writes the new
    /// survey's dataset `out` (nothing is written on failure). The project is not changed: add
    /// the survey with `add_placed_survey(…, out, AlignMode::Colmap)` in a `commit`.
    pub fn register_survey_photos(
        &self,
        photos: &Path,
        out: &Path,
        options: &PoseOptions,
        progress: &dyn Fn(Progress),
    ) -> Result<RegisterSummary, TimelineError> {
        let (_, reference) = self.colmap_reference()?;
        Ok(register_photos(&reference, photos, out, options, progress)?)
    }

    /// `survey` (of the registered dataset `dataset`) given the registered new photos as views
    /// and the alignment of the survey registered into; returns the record to keep.
    pub(crate) fn place_registered(
        &self,
        survey: &mut Survey,
        dataset: &Path,
    ) -> Result<SurveyRegistration, TimelineError> {
        let registration = RegisterSummary::read(dataset)?.ok_or_else(|| TimelineError::Io {
            path: dataset.to_path_buf(),
            message: "has no register.json: `--align colmap` adds a dataset that `twin \
                      add-survey --photos` registered (or give --photos)"
                .into(),
        })?;
        let reference = self
            .project
            .surveys
            .iter()
            .find(|s| same_folder(&self.resolve(&s.dataset), &registration.reference))
            .ok_or_else(|| TimelineError::Io {
                path: dataset.to_path_buf(),
                message: format!(
                    "was registered into {}, which is no survey's dataset in this twin",
                    registration.reference.display()
                ),
            })?;
        if registration.registered.is_empty() {
            return Err(TimelineError::Io {
                path: dataset.to_path_buf(),
                message: "registered no new photo".into(),
            });
        }
        survey.views = Some(
            registration
                .registered
                .iter()
                .map(|n| stem_of(Path::new(n)))
                .collect(),
        );
        survey.alignment = reference.alignment.clone();
        Ok(SurveyRegistration {
            reference_survey: reference.name.clone(),
            registration,
        })
    }

    /// Survey `name`'s registration record, where it was registered by COLMAP.
    pub fn load_registration(
        &self,
        name: &str,
    ) -> Result<Option<SurveyRegistration>, TimelineError> {
        let path = self.survey_file(name, REGISTRATION_FILE)?;
        if !crate::scene::files::is_present(&path) {
            return Ok(None);
        }
        read_json(&path).map(Some)
    }
}

impl SurveyRegistration {
    /// One line on the residual, for `twin status` and the report.
    pub fn describe(&self) -> String {
        let r = &self.registration;
        let s = &r.residual;
        format!(
            "{} of {} photos registered into survey {}'s model by COLMAP: new photos' points \
             {:.2} px ({} points); old poses moved {:.3}° / {:.4} units at most ({:.3} % of their \
             spread), old focal length {:.3} %",
            r.registered.len(),
            r.photos,
            self.reference_survey,
            s.new_reprojection_error_px,
            s.new_points,
            s.old_rotation_change_max_deg,
            s.old_position_change_max,
            100.0 * s.old_position_change_max / s.old_camera_spread.max(f64::MIN_POSITIVE),
            100.0 * s.old_focal_change_relative
        )
    }
}
