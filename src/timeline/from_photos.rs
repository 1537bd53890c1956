//! The app's "New twin from photos…" and "Add survey from photos…" as jobs: COLMAP's work
//! (`scene::sfm::pose_photos`, `Twin::register_survey_photos`) with its stages as the job's
//! progress and the job's Cancel killing COLMAP (`JobContext::cancel_flag`), then the project
//! steps `twin new` and `twin add-survey --photos` take. All or nothing: a cancel or a failure at
//! any step leaves no dataset (COLMAP's staging folder goes with the run; a dataset written
//! before a later step failed or was cancelled is removed) and no survey or project file.

use std::path::{Path, PathBuf};

use crate::scene::project::{Project, Survey};
use crate::scene::sfm::georef::Georeference;
use crate::scene::sfm::pose::{PoseOptions, PoseSummary, pose_photos};
use crate::scene::sfm::register::RegisterSummary;
use crate::scene::sfm::{Progress as SfmProgress, SfmError};
use crate::timeline::add_survey::{AddedSurvey, SurveyToAdd, add_in_job};
use crate::timeline::lock::Writer;
use crate::timeline::survey::AlignMode;
use crate::timeline::twin::{TimelineError, Twin};
use crate::train::job::{Job, JobContext, JobError, JobOptions, Progress};

/// A new twin project from a folder of photos.
#[derive(Clone, Debug)]
pub struct TwinFromPhotos {
    /// The photos (JPEG, PNG; masks beside them as `pose` takes them).
    pub photos: PathBuf,
    /// The dataset `pose` writes (new, or an empty folder).
    pub dataset: PathBuf,
    /// The project folder (must not hold a project yet).
    pub project: PathBuf,
    /// Its first survey.
    pub survey: String,
    pub date: String,
    pub pose: PoseOptions,
    /// Who writes the project (the lock file names it to other writers).
    pub writer: Writer,
}

/// A twin made from photos: the project as committed (its survey has no model yet) and what
/// COLMAP did.
#[derive(Clone, Debug)]
pub struct PosedTwin {
    pub twin: Twin,
    pub summary: PoseSummary,
}

/// COLMAP's progress as the job's: its stage as the phase ("features", "matching", "mapping",
/// "writing").
fn report_colmap<'a>(ctx: &'a JobContext<'_>) -> impl Fn(SfmProgress) + 'a {
    move |p| {
        ctx.progress(Progress::counted(p.stage.label(), p.done, p.total, 0));
    }
}

/// The twin project `request` describes, checked before COLMAP's minutes: a project already in
/// the folder, a bad survey name or date are refused at once.
fn check_new_twin(request: &TwinFromPhotos) -> Result<(), TimelineError> {
    let file = request.project.join(crate::scene::project::PROJECT_FILE);
    if file.exists() {
        return Err(TimelineError::Exists { file });
    }
    let mut check = Project::new();
    check
        .add_survey(Survey {
            name: request.survey.clone(),
            date: request.date.clone(),
            dataset: request.dataset.clone(),
            ..Default::default()
        })
        .map_err(|problem| TimelineError::Survey { file, problem })?;
    Ok(())
}

/// Poses the photos into the dataset, then creates the project with it as its first survey and
/// the dataset's georeference as its metres (as `twin new` does; no model is trained: the viewer
/// trains it). `None`: cancelled, nothing written.
pub fn new_twin_from_photos(
    ctx: &mut JobContext,
    request: &TwinFromPhotos,
) -> Result<Option<PosedTwin>, TimelineError> {
    check_new_twin(request)?;
    let options = PoseOptions {
        cancel: Some(ctx.cancel_flag()),
        ..request.pose.clone()
    };
    let summary = match pose_photos(
        &request.photos,
        &request.dataset,
        &options,
        &report_colmap(ctx),
    ) {
        Ok(summary) => summary,
        Err(SfmError::Cancelled) => return Ok(None),
        Err(e) => return Err(e.into()),
    };
    ctx.progress(Progress::counted("project", 0, 1, 0));
    let project_existed = request.project.exists();
    let made = (|| {
        if ctx.should_stop() {
            return Ok(None);
        }
        let mut twin = Twin::create(&request.project)?.with_writer(request.writer.clone());
        twin.commit(|twin| {
            twin.add_survey(&request.survey, &request.date, &request.dataset)?;
            if let Some(georef) = Georeference::read(&request.dataset)? {
                twin.project.settings.metres_per_unit = Some(georef.metres_per_unit());
            }
            Ok(())
        })?;
        Ok(Some(twin))
    })();
    match made {
        Ok(Some(twin)) => Ok(Some(PosedTwin { twin, summary })),
        other => {
            // The dataset was this run's: it goes with the project that did not come.
            remove_dataset(&request.dataset);
            if !project_existed {
                let _ = std::fs::remove_dir(&request.project);
            }
            other.map(|_| None)
        }
    }
}

/// [`new_twin_from_photos`] as a job.
pub fn new_twin_from_photos_job(
    request: TwinFromPhotos,
    options: JobOptions,
) -> Job<Option<PosedTwin>> {
    Job::spawn("pose", options, move |ctx| {
        ctx.log(format!(
            "posing the photos in {} with COLMAP into {}",
            request.photos.display(),
            request.dataset.display()
        ));
        new_twin_from_photos(ctx, &request).map_err(JobError::other)
    })
}

/// A later survey from photos: registered by COLMAP into the twin's posed survey (written as
/// `survey.dataset`), then added by the add-survey job's steps with `--align colmap`
/// (segmented first when asked).
pub fn add_survey_from_photos_job(
    twin: Twin,
    photos: PathBuf,
    survey: SurveyToAdd,
    pose: PoseOptions,
    options: JobOptions,
) -> Job<(Twin, Option<AddedSurvey>)> {
    Job::spawn("add-survey", options, move |ctx| {
        let mut twin = twin;
        let survey = SurveyToAdd {
            align: AlignMode::Colmap,
            dataset_must_open: true,
            ..survey
        };
        let registered =
            register_new_survey(ctx, &twin, &photos, &survey, &pose).map_err(JobError::other)?;
        let Some(summary) = registered else {
            return Ok((twin, None));
        };
        ctx.log(format!(
            "registered {} of {} photos by COLMAP{}",
            summary.registered.len(),
            summary.photos,
            match summary.unregistered.len() {
                0 => String::new(),
                _ => format!(" (not registered: {})", summary.unregistered.join(", ")),
            }
        ));
        let added = add_in_job(ctx, &mut twin, &survey);
        if !matches!(added, Ok(Some(_))) {
            remove_dataset(&survey.dataset);
        }
        Ok((twin, added?))
    })
}

/// The photos registered into `twin`'s posed survey as `survey.dataset`, after the survey's
/// name and date were checked against the project; `None`: cancelled, nothing written.
fn register_new_survey(
    ctx: &JobContext,
    twin: &Twin,
    photos: &Path,
    survey: &SurveyToAdd,
    pose: &PoseOptions,
) -> Result<Option<RegisterSummary>, TimelineError> {
    let mut check = twin.project.clone();
    check
        .add_survey(Survey {
            name: survey.name.clone(),
            date: survey.date.clone(),
            dataset: survey.dataset.clone(),
            ..Default::default()
        })
        .map_err(|problem| TimelineError::Survey {
            file: twin.file(),
            problem,
        })?;
    ctx.log(format!(
        "registering the photos in {} by COLMAP into {}",
        photos.display(),
        survey.dataset.display()
    ));
    let options = PoseOptions {
        cancel: Some(ctx.cancel_flag()),
        ..pose.clone()
    };
    match twin.register_survey_photos(photos, &survey.dataset, &options, &report_colmap(ctx)) {
        Ok(summary) => Ok(Some(summary)),
        Err(TimelineError::Sfm(SfmError::Cancelled)) => Ok(None),
        Err(e) => Err(e),
    }
}

/// Removes a dataset this run wrote (best effort: the error that ended the run is reported).
fn remove_dataset(dataset: &Path) {
    let _ = std::fs::remove_dir_all(dataset);
}
