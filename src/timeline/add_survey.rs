//! Adding a later survey as one step, for `twin add-survey` and the app's "Add survey…" alike:
//! optionally its photos segmented first (`segment_survey`), then the survey placed by its
//! alignment and committed to the project (`Twin::commit`: under the lock, on the project as other
//! writers left it). All or nothing: when the segmentation fails or is cancelled, or the commit
//! is refused, the masks this run wrote into the dataset are removed again (a retry is not then
//! refused for masks "already there") and the project is unchanged.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::segment::{SegmentError, SegmentModel, SegmentSettings, SegmentSummary};
use crate::timeline::align::Registration;
use crate::timeline::segment_survey::NewSurvey;
use crate::timeline::survey::AlignMode;
use crate::timeline::twin::{TimelineError, Twin};
use crate::train::job::{Job, JobContext, JobError, JobOptions, Progress};

/// A survey to add.
#[derive(Clone, Debug, PartialEq)]
pub struct SurveyToAdd {
    pub name: String,
    pub date: String,
    pub dataset: PathBuf,
    pub align: AlignMode,
    /// Segment its photos with a model first (masks written into the dataset).
    pub segment: Option<SegmentWith>,
    /// Refuse a dataset that does not open as the twin would see it (the app's flow, where the
    /// folder was just picked). The CLI has always recorded a same-frame survey whose data is not
    /// in place yet, and still does.
    pub dataset_must_open: bool,
}

/// The ONNX model a survey's photos are segmented with, and how.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentWith {
    pub model: PathBuf,
    pub settings: SegmentSettings,
}

impl SurveyToAdd {
    fn new_survey(&self) -> NewSurvey<'_> {
        NewSurvey {
            name: &self.name,
            date: &self.date,
            dataset: &self.dataset,
            align: self.align,
        }
    }
}

/// Where adding a survey is, for progress and cancel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AddStep {
    /// Photos segmented so far, of all.
    Segment { done: usize, total: usize },
    /// About to commit the survey to the project (the last moment to cancel).
    Commit,
}

/// A survey added.
#[derive(Clone, Debug, PartialEq)]
pub struct AddedSurvey {
    pub name: String,
    /// Its index in the project's surveys.
    pub index: usize,
    /// Its views as the twin sees them, where known (a joint model's new images; a dataset
    /// opened because it had to).
    pub views: Option<usize>,
    pub registration: Option<Registration>,
    /// How it was placed.
    pub align: AlignMode,
    /// The segmentation, with the threads it ran on.
    pub segmented: Option<(SegmentSummary, usize)>,
    pub dataset: PathBuf,
}

impl AddedSurvey {
    /// What happened, one line per fact, as the CLI prints it and the app logs it.
    pub fn lines(&self) -> Vec<String> {
        let mut lines = match &self.segmented {
            Some((summary, threads)) => summary.lines(*threads, &self.dataset),
            None => Vec::new(),
        };
        lines.push(match &self.registration {
            Some(r) => format!(
                "added survey {} ({} views), registered through {} shared images ({} kept): \
                 residual {:.4} units RMS ({:.3} % of the cameras' spread), scale {:.4}",
                self.name,
                self.views.unwrap_or(0),
                r.shared,
                r.inliers,
                r.residual,
                100.0 * r.relative_residual,
                r.similarity.scale
            ),
            None if self.align == AlignMode::Colmap => {
                format!("added survey {} (registered by COLMAP)", self.name)
            }
            None => format!("added survey {} (same frame)", self.name),
        });
        lines
    }
}

/// Adds `survey` to `twin` (segmenting its photos first when asked). `on_step` hears the
/// progress; returning false cancels, and a cancelled add returns `None` with nothing changed.
pub fn add_new_survey(
    twin: &mut Twin,
    survey: &SurveyToAdd,
    on_step: &mut dyn FnMut(AddStep) -> bool,
) -> Result<Option<AddedSurvey>, TimelineError> {
    let mut views = None;
    if survey.dataset_must_open {
        // Named as given (the project would name it relative to its folder).
        if !survey.dataset.is_dir() {
            let problem = match survey.dataset.exists() {
                true => "is not a folder: a survey's dataset is a folder",
                false => "does not exist: a survey's dataset is a folder",
            };
            return Err(TimelineError::Io {
                path: survey.dataset.clone(),
                message: problem.into(),
            });
        }
        // Checked on a copy as it would be added (name, date, registration), before any work.
        let mut check = twin.clone();
        check.add_placed_survey(&survey.name, &survey.date, &survey.dataset, survey.align)?;
        views = Some(check.open_survey_dataset(&survey.name)?.views.len());
    }
    let written = survey
        .segment
        .as_ref()
        .map(|with| WrittenMasks::before(&survey.dataset, &with.settings));
    let undo = |e: TimelineError| {
        if let Some(w) = &written {
            w.remove_new();
        }
        e
    };
    let segmented = match &survey.segment {
        Some(with) => {
            let model = SegmentModel::open(&with.model, with.settings.classes.len())
                .map_err(TimelineError::from)?;
            let result = twin.segment_new_survey(
                survey.new_survey(),
                &model,
                &with.settings,
                &mut |done, total| on_step(AddStep::Segment { done, total }),
            );
            match result {
                Ok(summary) => Some((summary, rayon::current_num_threads())),
                Err(TimelineError::Segment(SegmentError::Cancelled)) => {
                    undo(TimelineError::Segment(SegmentError::Cancelled));
                    return Ok(None);
                }
                Err(e) => return Err(undo(e)),
            }
        }
        None => None,
    };
    if !on_step(AddStep::Commit) {
        undo(TimelineError::Segment(SegmentError::Cancelled));
        return Ok(None);
    }
    // Added to the project as it is when the lock is held: another survey added meanwhile stays.
    let registration = twin
        .commit(|twin| {
            twin.add_placed_survey(&survey.name, &survey.date, &survey.dataset, survey.align)
        })
        .map_err(undo)?;
    let index = twin.survey_index(&survey.name)?;
    if let Some(placed) = &twin.project.surveys[index].views {
        views = Some(placed.len());
    }
    Ok(Some(AddedSurvey {
        name: survey.name.clone(),
        index,
        views,
        registration,
        align: survey.align,
        segmented,
        dataset: survey.dataset.clone(),
    }))
}

/// [`add_new_survey`] as a job (the app's "Add survey…", `twin add-survey`): progress in photos
/// segmented, then one step for the commit; cancel stops before the commit. The project as
/// committed comes back with the survey (`None`: cancelled, nothing changed).
pub fn add_survey_job(
    mut twin: Twin,
    survey: SurveyToAdd,
    options: JobOptions,
) -> Job<(Twin, Option<AddedSurvey>)> {
    Job::spawn("add-survey", options, move |ctx| {
        let added = add_in_job(ctx, &mut twin, &survey)?;
        Ok((twin, added))
    })
}

/// [`add_new_survey`] inside a job (`add_survey_job`, and after COLMAP registered the photos,
/// `from_photos`): its steps as the job's progress, the job's cancel as the answer.
pub fn add_in_job(
    ctx: &mut JobContext,
    twin: &mut Twin,
    survey: &SurveyToAdd,
) -> Result<Option<AddedSurvey>, JobError> {
    if let Some(with) = &survey.segment {
        ctx.log(format!(
            "segmenting survey {} with {}",
            survey.name,
            with.model.display()
        ));
    }
    add_new_survey(twin, survey, &mut |step| {
        let progress = match step {
            AddStep::Segment { done, total } => Progress::counted("segment", done, total, 0),
            AddStep::Commit => Progress::counted("add", 0, 1, 0),
        };
        ctx.progress(progress);
        !ctx.should_stop()
    })
    .map_err(JobError::other)
}

/// The mask and probability files of the segmented classes in a dataset before a run, so that a
/// run that does not end in a commit removes exactly what it wrote (files, and the folders it
/// made), and nothing that was there before.
struct WrittenMasks {
    /// `masks/<class>` and `probabilities/<class>` of every class written.
    class_folders: Vec<PathBuf>,
    /// Those and `masks/`, `probabilities/` that did not exist: removed when empty again.
    made: Vec<PathBuf>,
    /// The files in the class folders before.
    files: BTreeSet<PathBuf>,
}

impl WrittenMasks {
    fn before(root: &Path, settings: &SegmentSettings) -> WrittenMasks {
        let kinds = ["masks", "probabilities"];
        let mut class_folders = Vec::new();
        for class in settings.written_classes() {
            for kind in kinds {
                class_folders.push(root.join(kind).join(class.id()));
            }
        }
        // Class folders first: a parent is removed only after its children.
        let made = class_folders
            .iter()
            .cloned()
            .chain(kinds.iter().map(|k| root.join(k)))
            .filter(|f| !f.exists())
            .collect();
        let files = class_folders.iter().flat_map(|f| entries(f)).collect();
        WrittenMasks {
            class_folders,
            made,
            files,
        }
    }

    /// Removes the files the run added and the folders it made. Best effort: the error that
    /// ended the run is the one reported, and a file left behind is refused by name next time.
    fn remove_new(&self) {
        for folder in &self.class_folders {
            for path in entries(folder) {
                if !self.files.contains(&path) && path.is_file() {
                    let _ = std::fs::remove_file(&path);
                }
            }
        }
        for folder in &self.made {
            let _ = std::fs::remove_dir(folder);
        }
    }
}

/// The paths in `folder` (none when it cannot be listed).
fn entries(folder: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(folder)
        .map(|list| list.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default()
}
