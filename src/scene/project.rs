//! The twin project file `twin.ron`: format version, damage classes and colours, surveys in
//! date order (inputs and outputs by path), and a few settings. Loading refuses files from a
//! newer program; saving is atomic. Holds paths only; never opens the datasets or models.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::scene::atomic::{PendingFile, write_pending};
use crate::scene::files::read_text;
use crate::scene::limits::{MAX_IMAGE_SIDE, MAX_PROJECT_BYTES};
use crate::scene::survey_name::{BadSurveyName, check_survey_name, same_survey_name};
use crate::scene::{DamageClass, NEW_DAMAGE_COLOUR};
use crate::scene::{ImageScale, SceneError};

/// The newest `twin.ron` format this program reads and the one it writes.
/// 2: surveys gained `alignment`, `views`, `changes` and `appearance` (a version-1 program would
/// ignore an alignment and misplace the survey, so it must refuse these files).
pub const PROJECT_FORMAT_VERSION: u32 = 2;

/// The project file's name inside a project folder.
pub const PROJECT_FILE: &str = "twin.ron";

/// A damage class and the colour it is drawn in.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClassStyle {
    pub class: DamageClass,
    pub colour: [u8; 3],
}

/// One survey (a capture of the structure at one date): its inputs and, once trained, outputs.
/// Relative paths are relative to the folder holding `twin.ron` (see `Project::resolve`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Survey {
    pub name: String,
    /// ISO date `YYYY-MM-DD`; surveys are kept in this order (ties keep insertion order).
    pub date: String,
    /// The dataset folder (COLMAP or transforms.json), with `masks/` beside its images.
    pub dataset: PathBuf,
    /// The trained model PLY, once there is one.
    #[serde(default)]
    pub model: Option<PathBuf>,
    /// Metrics JSON of the last evaluation.
    #[serde(default)]
    pub metrics: Option<PathBuf>,
    /// Where the dataset's frame sits in the twin's (None: its poses already are in the twin's
    /// frame).
    #[serde(default)]
    pub alignment: Option<Alignment>,
    /// The dataset's views that belong to this survey (None: all); a joint COLMAP model also
    /// holds the earlier surveys' images.
    #[serde(default)]
    pub views: Option<Vec<String>>,
    /// The folder of this survey's change maps, once changes were detected.
    #[serde(default)]
    pub changes: Option<PathBuf>,
    /// The survey's appearance relative to the twin's colours (lighting differs between surveys).
    #[serde(default)]
    pub appearance: Option<ColourTransform>,
}

impl Survey {
    /// Checks that `name` can name a survey (`survey_name::check_survey_name`), as the error
    /// adding such a survey would give.
    pub fn check_name(name: &str) -> Result<(), SurveyError> {
        check_survey_name(name).map_err(|why| SurveyError::BadName {
            name: name.to_string(),
            why,
        })
    }

    /// The survey's outputs that `twin.ron` names, with their field names. They are the
    /// project's own files, so they must lie inside its folder; the dataset is an input and may
    /// lie anywhere (`twin new --dataset` stores it relative to the project, `../data/…`).
    pub fn outputs(&self) -> impl Iterator<Item = (&'static str, &Path)> {
        [
            ("model", &self.model),
            ("metrics", &self.metrics),
            ("changes", &self.changes),
        ]
        .into_iter()
        .filter_map(|(field, path)| path.as_deref().map(|p| (field, p)))
    }

    /// Checks that the alignment and appearance hold finite numbers (a NaN rotation or colour
    /// gain would spread through every render and measurement of the survey); the error starts
    /// with the field.
    fn check_numbers(&self) -> Result<(), String> {
        let finite = |values: &[f64]| values.iter().all(|v| v.is_finite());
        if let Some(a) = &self.alignment {
            // The residual only reports the fit; the transform itself must be usable.
            let numbers = [&a.rotation[..], &a.translation[..], &[a.scale]].concat();
            if !finite(&numbers) || !(a.scale > 0.0) {
                return Err(
                    "alignment holds a number that is not finite (or a scale that is not positive)"
                        .to_string(),
                );
            }
        }
        if let Some(t) = &self.appearance {
            let numbers: Vec<f64> = t
                .matrix
                .iter()
                .flatten()
                .chain(&t.offset)
                .map(|&v| f64::from(v))
                .collect();
            if !finite(&numbers) {
                return Err("appearance holds a number that is not finite".to_string());
            }
        }
        Ok(())
    }
}

/// Whether `path`, relative to the project folder, stays below it: not empty, not absolute, no
/// `..`. Lexical only; `timeline::Twin` also refuses links that lead out.
pub fn stays_inside(path: &Path) -> bool {
    use std::path::Component;
    !path.as_os_str().is_empty()
        && path
            .components()
            .all(|c| matches!(c, Component::Normal(_) | Component::CurDir))
        && path.components().any(|c| matches!(c, Component::Normal(_)))
}

/// A similarity from a dataset's frame to the twin's, `x_twin = scale·R·x + translation`, and
/// how well it was fitted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Alignment {
    pub scale: f64,
    /// Unit quaternion `(x, y, z, w)`.
    pub rotation: [f64; 4],
    pub translation: [f64; 3],
    /// RMS camera-centre distance after the fit, in twin units, and the images it used.
    pub residual: f64,
    pub shared: usize,
    pub inliers: usize,
}

/// An affine colour transform: `photo = matrix · twin_colour + offset` (rows of `matrix`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColourTransform {
    pub matrix: [[f32; 3]; 3],
    pub offset: [f32; 3],
}

impl ColourTransform {
    pub const IDENTITY: ColourTransform = ColourTransform {
        matrix: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        offset: [0.0; 3],
    };

    fn matrix(&self) -> glam::Mat3 {
        glam::Mat3::from_cols_array_2d(&self.matrix).transpose()
    }

    /// Applies `photo = M · colour + o` to an image in place.
    pub fn apply(&self, image: &mut crate::scene::RgbImage) {
        let (m, o) = (self.matrix(), glam::Vec3::from_array(self.offset));
        for rgb in image.data.chunks_exact_mut(3) {
            let v = m * glam::Vec3::new(rgb[0], rgb[1], rgb[2]) + o;
            rgb.copy_from_slice(&v.to_array());
        }
    }

    /// The inverse, `colour = M⁻¹ (photo − o)`, in place and clamped to [0, 1]: a photo as it
    /// would look in the twin's light. Leaves the image as it is when `M` is singular.
    pub fn undo(&self, photo: &mut crate::scene::RgbImage) {
        let m = self.matrix();
        if !(m.determinant().abs() > 1e-6) {
            return;
        }
        let (inverse, o) = (m.inverse(), glam::Vec3::from_array(self.offset));
        for rgb in photo.data.chunks_exact_mut(3) {
            let v = inverse * (glam::Vec3::new(rgb[0], rgb[1], rgb[2]) - o);
            rgb.copy_from_slice(&v.clamp(glam::Vec3::ZERO, glam::Vec3::ONE).to_array());
        }
    }
}

/// Checks a scale in metres per model unit: a positive finite number (0 would measure every
/// region as nothing, a negative or NaN one breaks the plane fit). The error names no field;
/// the caller says where the value came from.
pub fn check_metres_per_unit(metres_per_unit: f64) -> Result<(), String> {
    if metres_per_unit.is_finite() && metres_per_unit > 0.0 {
        return Ok(());
    }
    Err(format!(
        "{metres_per_unit} is not a scale: metres per model unit must be a positive finite number"
    ))
}

/// Project-wide settings. Every field has a default, so files written before a field existed
/// still load.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ProjectSettings {
    /// Background colour for rendering and for compositing RGBA images.
    pub background: [f32; 3],
    /// The resolution the project's surveys are worked at: the first survey's training scale
    /// (`twin new --scale`, the app's training resolution), and the default of `twin update`
    /// and `twin detect` and of the app's update and detection.
    pub scale: ImageScale,
    /// Colour of damage that appeared after an earlier survey.
    pub new_damage_colour: [u8; 3],
    /// Every n-th image is held out for evaluation (the 3DGS convention is 8).
    pub held_out_every: u32,
    /// Metres per model unit, once known (`twin set-scale`; a synthetic survey is metric).
    /// Structure from motion is up to scale: without it, quantities are in model units.
    pub metres_per_unit: Option<f64>,
    /// The survey the viewer showed when the project was last saved from it (None: the latest).
    pub shown_survey: Option<String>,
}

impl Default for ProjectSettings {
    fn default() -> Self {
        ProjectSettings {
            background: [0.0; 3],
            scale: ImageScale::Factor(1),
            new_damage_colour: NEW_DAMAGE_COLOUR,
            held_out_every: 8,
            metres_per_unit: None,
            shown_survey: None,
        }
    }
}

/// The twin project.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Project {
    pub format_version: u32,
    pub classes: Vec<ClassStyle>,
    /// Surveys in date order; a Gaussian's `survey` index points into this list.
    pub surveys: Vec<Survey>,
    #[serde(default)]
    pub settings: ProjectSettings,
}

/// Why a survey cannot be added.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SurveyError {
    #[error("survey name `{}` {why}", name.escape_debug())]
    BadName { name: String, why: BadSurveyName },
    #[error("survey `{name}`: date `{date}` is not YYYY-MM-DD")]
    BadDate { name: String, date: String },
    #[error(
        "survey `{name}` ({date}) is older than the latest survey `{latest}` ({latest_date}); surveys are indexed in date order"
    )]
    OutOfOrder {
        name: String,
        date: String,
        latest: String,
        latest_date: String,
    },
    /// Names compare without case: on macOS and Windows they would share a folder.
    #[error("a survey named `{0}` already exists")]
    Duplicate(String),
}

/// Only the version, read first so that a newer file is refused before its fields are parsed.
#[derive(Deserialize)]
#[serde(rename = "Project")]
struct VersionProbe {
    format_version: u32,
}

fn is_iso_date(date: &str) -> bool {
    let b = date.as_bytes();
    b.len() == 10
        && b[4] == b'-'
        && b[7] == b'-'
        && b.iter()
            .enumerate()
            .all(|(i, c)| i == 4 || i == 7 || c.is_ascii_digit())
        && (1..=12).contains(&date[5..7].parse::<u32>().unwrap_or(0))
        && (1..=31).contains(&date[8..10].parse::<u32>().unwrap_or(0))
}

impl Default for Project {
    fn default() -> Self {
        Project::new()
    }
}

impl Project {
    /// An empty project with the default classes and colours.
    pub fn new() -> Project {
        Project {
            format_version: PROJECT_FORMAT_VERSION,
            classes: DamageClass::ALL
                .into_iter()
                .map(|class| ClassStyle {
                    class,
                    colour: class.default_colour(),
                })
                .collect(),
            surveys: Vec::new(),
            settings: ProjectSettings::default(),
        }
    }

    /// The colour of a class (its default when the project does not list it).
    pub fn colour(&self, class: DamageClass) -> [u8; 3] {
        self.classes
            .iter()
            .find(|s| s.class == class)
            .map_or(class.default_colour(), |s| s.colour)
    }

    /// Appends a survey, which must not be older than the latest one (indices must not shift).
    /// Returns its index.
    pub fn add_survey(&mut self, survey: Survey) -> Result<usize, SurveyError> {
        Survey::check_name(&survey.name)?;
        if !is_iso_date(&survey.date) {
            return Err(SurveyError::BadDate {
                name: survey.name,
                date: survey.date,
            });
        }
        if let Some(taken) = self
            .surveys
            .iter()
            .find(|s| same_survey_name(&s.name, &survey.name))
        {
            return Err(SurveyError::Duplicate(taken.name.clone()));
        }
        if let Some(latest) = self.surveys.last()
            && survey.date < latest.date
        {
            return Err(SurveyError::OutOfOrder {
                name: survey.name,
                date: survey.date,
                latest: latest.name.clone(),
                latest_date: latest.date.clone(),
            });
        }
        self.surveys.push(survey);
        Ok(self.surveys.len() - 1)
    }

    /// A path from the project file made usable: relative paths join the project file's folder.
    pub fn resolve(project_file: &Path, path: &Path) -> PathBuf {
        if path.is_absolute() {
            return path.to_path_buf();
        }
        project_file
            .parent()
            .map_or_else(|| path.to_path_buf(), |dir| dir.join(path))
    }

    /// Checks what the types cannot: names (`survey_name`), date format and order, outputs
    /// inside the project folder, a background colour, a known scale.
    fn validate(&self) -> Result<(), String> {
        let mut check = Project {
            surveys: Vec::new(),
            ..self.clone()
        };
        for (index, survey) in self.surveys.iter().enumerate() {
            check.add_survey(survey.clone()).map_err(|e| match e {
                SurveyError::BadName { .. } => format!("surveys[{index}].name: {e}"),
                _ => e.to_string(),
            })?;
            let named =
                std::iter::once(("dataset", survey.dataset.as_path())).chain(survey.outputs());
            for (field, path) in named {
                // A line break or another control character in a path is a damaged file (the
                // fuzz harness found such paths split every message naming them over lines).
                if path.to_string_lossy().chars().any(char::is_control) {
                    return Err(format!(
                        "surveys[{index}].{field} {:?} holds a control character; no path of a \
                         project does",
                        path.to_string_lossy()
                    ));
                }
            }
            for (field, path) in survey.outputs() {
                if !stays_inside(path) {
                    return Err(format!(
                        "surveys[{index}].{field} `{}` is not a path inside the project folder \
                         (a survey's outputs are stored relative to it, below it)",
                        path.display()
                    ));
                }
            }
        }
        let bg = self.settings.background;
        if !bg.iter().all(|v| (0.0..=1.0).contains(v)) {
            return Err(format!(
                "settings.background {bg:?} is not a colour in [0, 1]"
            ));
        }
        if let Some(k) = self.settings.metres_per_unit {
            check_metres_per_unit(k).map_err(|m| format!("settings.metres_per_unit {m}"))?;
        }
        for (index, survey) in self.surveys.iter().enumerate() {
            survey
                .check_numbers()
                .map_err(|m| format!("surveys[{index}].{m}"))?;
        }
        if !self.settings.scale.is_valid() {
            return Err(format!(
                "settings.scale {:?} is not a factor 1, 2, 4 or 8 or a width 1 to {MAX_IMAGE_SIDE}",
                self.settings.scale
            ));
        }
        Ok(())
    }

    /// Reads `twin.ron`. A newer format version than `PROJECT_FORMAT_VERSION` is refused
    /// before anything else is interpreted.
    pub fn load(path: &Path) -> Result<Project, SceneError> {
        let text = read_text(path, MAX_PROJECT_BYTES)?;
        let probe: VersionProbe = ron::from_str(&text)
            .map_err(|e| SceneError::invalid(path, format!("not a twin project file: {e}")))?;
        if probe.format_version > PROJECT_FORMAT_VERSION {
            return Err(SceneError::unsupported(
                path,
                format!(
                    "project format version {} was written by a newer damage-twin; this one reads \
                     versions up to {PROJECT_FORMAT_VERSION} — update damage-twin to open it",
                    probe.format_version
                ),
            ));
        }
        if probe.format_version == 0 {
            return Err(SceneError::invalid(
                path,
                "project format version 0 does not exist",
            ));
        }
        let project: Project = ron::from_str(&text)
            .map_err(|e| SceneError::invalid(path, format!("bad twin project: {e}")))?;
        project
            .validate()
            .map_err(|m| SceneError::invalid(path, m))?;
        Ok(project)
    }

    /// Writes `twin.ron` atomically (temporary file, fsync, rename, fsync of the folder), in
    /// the current format version.
    pub fn save(&self, path: &Path) -> Result<(), SceneError> {
        self.save_pending(path)?.commit()
    }

    /// `save` up to the rename: the new `twin.ron` written and synced beside the old one, put in
    /// its place by `PendingFile::commit` (a twin commit renames it last, after its survey
    /// folders).
    pub fn save_pending(&self, path: &Path) -> Result<PendingFile, SceneError> {
        self.validate()
            .map_err(|m| SceneError::invalid(path, format!("cannot save: {m}")))?;
        let current = Project {
            format_version: PROJECT_FORMAT_VERSION,
            ..self.clone()
        };
        let config = ron::ser::PrettyConfig::new().struct_names(true);
        let text = ron::ser::to_string_pretty(&current, config)
            .map_err(|e| SceneError::invalid(path, format!("cannot serialise: {e}")))?;
        write_pending(path, |w| {
            use std::io::Write;
            w.write_all(text.as_bytes())?;
            w.write_all(b"\n")
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn survey(name: &str, date: &str) -> Survey {
        Survey {
            name: name.into(),
            date: date.into(),
            dataset: PathBuf::from(format!("surveys/{name}")),
            model: Some(PathBuf::from(format!("surveys/{name}/model.ply"))),
            ..Survey::default()
        }
    }

    #[test]
    fn project_round_trips_through_twin_ron() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(PROJECT_FILE);
        let mut project = Project::new();
        project.classes[0].colour = [0, 0, 255];
        project.settings.background = [1.0, 1.0, 1.0];
        project.settings.scale = ImageScale::Width(960);
        assert_eq!(project.add_survey(survey("before", "2024-03-01")), Ok(0));
        assert_eq!(project.add_survey(survey("after", "2024-09-15")), Ok(1));
        project.save(&path).unwrap();
        let loaded = Project::load(&path).unwrap();
        assert_eq!(loaded, project);
        assert_eq!(loaded.colour(DamageClass::Crack), [0, 0, 255]);
        // Only twin.ron remains: the temporary file was renamed, not left behind.
        let files: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(files.len(), 1);
    }

    #[test]
    fn surveys_must_come_in_date_order_with_valid_dates() {
        let mut project = Project::new();
        project.add_survey(survey("b", "2024-05-01")).unwrap();
        assert!(matches!(
            project.add_survey(survey("a", "2023-01-01")),
            Err(SurveyError::OutOfOrder { .. })
        ));
        assert!(matches!(
            project.add_survey(survey("c", "2024-13-01")),
            Err(SurveyError::BadDate { .. })
        ));
        assert!(matches!(
            project.add_survey(survey("b", "2025-01-01")),
            Err(SurveyError::Duplicate(_))
        ));
        // `B` and `b` would share a folder on macOS and Windows.
        assert_eq!(
            project.add_survey(survey("B", "2025-01-01")),
            Err(SurveyError::Duplicate("b".into()))
        );
        assert!(matches!(
            project.add_survey(survey("../b", "2025-01-01")),
            Err(SurveyError::BadName { .. })
        ));
    }

    #[test]
    fn newer_format_version_is_refused_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(PROJECT_FILE);
        let text = format!(
            "Project(format_version: {}, classes: [], surveys: [], hologram: true)",
            PROJECT_FORMAT_VERSION + 1
        );
        std::fs::write(&path, text).unwrap();
        let err = Project::load(&path).unwrap_err().to_string();
        assert!(err.contains("twin.ron") && err.contains("newer"), "{err}");
    }

    #[test]
    fn relative_paths_resolve_beside_the_project_file() {
        let p = Project::resolve(Path::new("/proj/twin.ron"), Path::new("s1/model.ply"));
        assert_eq!(p, PathBuf::from("/proj/s1/model.ply"));
    }
}
