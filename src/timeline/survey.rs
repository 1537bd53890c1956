//! A survey's dataset as the twin sees it: its own views only (a joint model also holds the
//! earlier surveys' images) with every pose in the twin's frame; and adding a survey, placed
//! `same-frame` (its poses already are in the twin's frame), `joint` (registered through the
//! images it shares with the twin's latest survey) or `colmap` (registered by COLMAP into an
//! earlier survey's model, `register_survey`).

use std::path::Path;

use glam::DVec3;
use serde::Serialize;

use crate::scene::open::OpenOptions;
use crate::scene::project::{Alignment, Survey};
use crate::scene::{Camera, Dataset};
use crate::timeline::align::{Registration, Similarity, register};
use crate::timeline::register_survey::REGISTRATION_FILE;
use crate::timeline::twin::{TimelineError, Twin};

/// How a new survey is placed in the twin's frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum AlignMode {
    /// The dataset's poses are in the twin's frame (the synthetic surveys).
    SameFrame,
    /// A COLMAP model of the earlier survey's images and the new ones in a frame of its own.
    Joint,
    /// A dataset registered by COLMAP into an earlier survey's model, its poses held
    /// (`twin add-survey --photos`, `register_survey`): that survey's frame.
    Colmap,
}

impl AlignMode {
    /// The alignments the app offers for a posed dataset, in order. `Colmap` is not among them:
    /// it takes photos that COLMAP registers first (`twin add-survey --photos`), which the app
    /// does not do yet.
    pub const ALL: [AlignMode; 2] = [AlignMode::SameFrame, AlignMode::Joint];

    /// The name `--align` takes.
    pub fn name(self) -> &'static str {
        match self {
            AlignMode::SameFrame => "same-frame",
            AlignMode::Joint => "joint",
            AlignMode::Colmap => "colmap",
        }
    }
}

impl std::str::FromStr for AlignMode {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "same-frame" => Ok(AlignMode::SameFrame),
            "joint" => Ok(AlignMode::Joint),
            "colmap" => Ok(AlignMode::Colmap),
            _ => Err(format!(
                "unknown alignment {text:?}: use same-frame, joint or colmap"
            )),
        }
    }
}

impl Alignment {
    fn similarity(&self) -> Similarity {
        Similarity {
            scale: self.scale,
            rotation: self.rotation,
            translation: self.translation,
        }
    }
}

/// `dataset` restricted to `views` (by name; None keeps all) with `alignment` applied to every
/// camera and point.
pub fn place(
    mut dataset: Dataset,
    views: Option<&[String]>,
    alignment: Option<&Alignment>,
) -> Dataset {
    if let Some(names) = views {
        dataset.views.retain(|v| names.iter().any(|n| n == &v.name));
    }
    if let Some(alignment) = alignment {
        let similarity = alignment.similarity();
        for view in &mut dataset.views {
            view.camera = similarity.apply_camera(&view.camera);
        }
        if let Some(points) = &mut dataset.points {
            for p in &mut points.positions {
                let q = similarity.apply(p.as_dvec3());
                *p = glam::Vec3::new(q.x as f32, q.y as f32, q.z as f32);
            }
        }
    }
    dataset
}

impl Twin {
    /// Opens survey `name`'s dataset as the twin sees it (its views, in the twin's frame).
    pub fn open_survey_dataset(&self, name: &str) -> Result<Dataset, TimelineError> {
        let survey = self.survey(name)?;
        let root = self.resolve(&survey.dataset);
        let options = OpenOptions {
            background: self.project.settings.background,
        };
        let dataset = Dataset::open(&root, &options)?;
        let placed = place(dataset, survey.views.as_deref(), survey.alignment.as_ref());
        if placed.views.is_empty() {
            return Err(TimelineError::Io {
                path: root,
                message: format!("survey `{name}` has no views there"),
            });
        }
        Ok(placed)
    }

    /// Adds survey `name` of `dataset`, placed by `align`. `joint` registers the dataset through
    /// the images it shares (by name) with the latest survey, keeps only its other images as
    /// the new survey's views, and stores the similarity. Returns the registration, if any.
    pub fn add_placed_survey(
        &mut self,
        name: &str,
        date: &str,
        dataset: &Path,
        align: AlignMode,
    ) -> Result<Option<Registration>, TimelineError> {
        let mut survey = Survey {
            name: name.to_string(),
            date: date.to_string(),
            dataset: self.relative(dataset),
            ..Survey::default()
        };
        let mut record = None;
        let registration = match align {
            AlignMode::SameFrame => None,
            AlignMode::Colmap => {
                record = Some(self.place_registered(&mut survey, dataset)?);
                None
            }
            AlignMode::Joint => {
                let latest = self.latest()?.name.clone();
                let twin_views = self.open_survey_dataset(&latest)?;
                let joint = Dataset::open(dataset, &OpenOptions::default())?;
                let pairs: Vec<(Camera, Camera)> = joint
                    .views
                    .iter()
                    .filter_map(|v| {
                        twin_views
                            .views
                            .iter()
                            .find(|t| t.name == v.name)
                            .map(|t| (v.camera, t.camera))
                    })
                    .collect();
                let registration = register(&pairs).map_err(|e| TimelineError::Io {
                    path: dataset.to_path_buf(),
                    message: e.to_string(),
                })?;
                // Every image of an earlier survey is old; the rest are this survey's.
                let mut old = std::collections::HashSet::new();
                for s in &self.project.surveys {
                    if let Ok(d) = self.open_survey_dataset(&s.name) {
                        old.extend(d.views.into_iter().map(|v| v.name));
                    }
                }
                let new: Vec<String> = joint
                    .views
                    .iter()
                    .map(|v| v.name.clone())
                    .filter(|n| !old.contains(n))
                    .collect();
                if new.is_empty() {
                    return Err(TimelineError::Io {
                        path: dataset.to_path_buf(),
                        message: "every image of the joint model belongs to an earlier survey: \
                                  nothing new to add"
                            .into(),
                    });
                }
                survey.views = Some(new);
                let s = &registration.similarity;
                survey.alignment = Some(Alignment {
                    scale: s.scale,
                    rotation: s.rotation,
                    translation: s.translation,
                    residual: registration.residual,
                    shared: registration.shared,
                    inliers: registration.inliers,
                });
                Some(registration)
            }
        };
        self.project
            .add_survey(survey)
            .map_err(|problem| TimelineError::Survey {
                file: self.file(),
                problem,
            })?;
        // Kept with the survey's other records when committed (a check on a copy writes none).
        if let Some(record) = record
            && self.is_committing()
        {
            self.write_survey_json(name, REGISTRATION_FILE, &record)?;
        }
        Ok(registration)
    }
}

/// The camera centres' spread of a dataset (RMS distance to their mean), for reporting a
/// registration residual in proportion.
pub fn camera_spread(dataset: &Dataset) -> f64 {
    let centres: Vec<DVec3> = dataset
        .views
        .iter()
        .map(|v| v.camera.position().as_dvec3())
        .collect();
    let n = centres.len().max(1) as f64;
    let mean = centres.iter().copied().sum::<DVec3>() / n;
    (centres
        .iter()
        .map(|c| c.distance_squared(mean))
        .sum::<f64>()
        / n)
        .sqrt()
}
