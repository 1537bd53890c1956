//! "Add survey…" in the viewer: the dialog's fields kept in the state (a file dialog fills them
//! from its worker), the survey added by `timeline::add_survey`'s job on a worker, as `twin
//! add-survey` adds it (segmented first when asked, committed under the project's lock, all or
//! nothing), its progress and cancel in the timeline strip, and the new survey in the strip when
//! it is done. The dialog stays open with the error line when the survey was not added (until a
//! field changes). "Add survey from photos…" is the same dialog and job with COLMAP's
//! registration first (`timeline::from_photos`).

use std::path::PathBuf;

use super::saving::viewer_writer;
use super::{AppState, TimelineJob, TimelineWork};
use crate::app::survey_form::AddSurveyForm;
use crate::scene::sfm::pose::PoseOptions;
use crate::timeline::Twin;
use crate::timeline::add_survey::{AddedSurvey, add_survey_job};
use crate::timeline::from_photos::add_survey_from_photos_job;
use crate::train::history::History;
use crate::train::job::JobOptions;

impl AppState {
    /// Opens the dialog for the open project (its fields kept when it is open already).
    pub(super) fn open_add_survey(&mut self) {
        let Some(timeline) = &self.timeline else {
            self.log_line("open a twin project to add a survey to it");
            return;
        };
        if self.add_survey.is_none() {
            self.add_survey = Some(AddSurveyForm::for_project(&timeline.twin));
        }
    }

    /// Opens the dialog for a survey from photos ("Add survey from photos…"); a dialog open for
    /// a dataset starts afresh, as it asks for other fields.
    pub(super) fn open_add_survey_from_photos(&mut self) {
        let Some(timeline) = &self.timeline else {
            self.log_line("open a twin project to add a survey to it");
            return;
        };
        if !self.add_survey.as_ref().is_some_and(|f| f.from_photos) {
            self.add_survey = Some(AddSurveyForm::for_project_from_photos(&timeline.twin));
        }
    }

    /// The panel's edited fields; a change of any field clears the last refusal, which was about
    /// the fields as they were.
    pub(super) fn edit_add_survey(&mut self, form: AddSurveyForm) {
        if let Some(old) = &mut self.add_survey {
            let changed = !old.same_inputs(&form);
            *old = form;
            if changed {
                old.error = None;
            }
        }
    }

    pub(super) fn choose_survey_photos(&mut self, folder: PathBuf) {
        if let (Some(form), Some(timeline)) = (&mut self.add_survey, &self.timeline) {
            form.choose_photos(&folder, &timeline.twin);
            form.error = None;
        }
    }

    pub(super) fn choose_survey_dataset(&mut self, folder: PathBuf) {
        if let (Some(form), Some(timeline)) = (&mut self.add_survey, &self.timeline) {
            form.choose_dataset(&folder, &timeline.twin);
            form.error = None;
        }
    }

    pub(super) fn choose_segment_model(&mut self, file: PathBuf) {
        if let Some(form) = &mut self.add_survey {
            form.model = file.display().to_string();
            form.error = None;
        }
    }

    /// Starts adding the survey the dialog describes; a form that describes none gets its error
    /// line.
    pub(super) fn start_add_survey(&mut self) {
        if self.timeline_job_refused() {
            return;
        }
        let (Some(form), Some(timeline)) = (&mut self.add_survey, &mut self.timeline) else {
            self.log_line("open a twin project and its \"Add survey…\" dialog first");
            return;
        };
        let request = form
            .request(timeline.twin.project.settings.background)
            .and_then(|r| Ok((r, form.photos_to_register()?)));
        let (request, photos) = match request {
            Ok(request) => request,
            Err(problem) => {
                form.error = Some(problem.clone());
                self.log_line(format!("cannot add the survey: {problem}"));
                return;
            }
        };
        form.error = None;
        let name = request.name.clone();
        let twin = timeline.twin.clone().with_writer(viewer_writer(true));
        let options = JobOptions {
            low_priority: true,
            ..JobOptions::default()
        };
        let job = match photos {
            Some(photos) => {
                add_survey_from_photos_job(twin, photos, request, PoseOptions::default(), options)
            }
            None => add_survey_job(twin, request, options),
        };
        timeline.job = Some(TimelineJob {
            work: TimelineWork::AddSurvey(job),
            survey: timeline.twin.project.surveys.len(),
            progress: None,
            history: History::default(),
            started: std::time::Instant::now(),
        });
        self.log_line(format!("adding survey {name}"));
    }

    /// The job's end: the project as committed, the new survey in the strip, the dialog closed
    /// (open with a line saying so when cancelled).
    pub(super) fn finish_add_survey(&mut self, (twin, added): (Twin, Option<AddedSurvey>)) {
        let Some(added) = added else {
            self.add_survey_failed("cancelled: nothing was added".into());
            return;
        };
        if let Some(t) = &mut self.timeline {
            t.twin = twin;
        }
        for line in added.lines() {
            self.log_line(line);
        }
        self.log_line(format!(
            "survey {} is in the timeline: update the twin with it, or detect its changes",
            added.name
        ));
        self.add_survey = None;
    }

    /// The survey was not added: why, in the dialog (reopened with the fields as they were).
    pub(super) fn add_survey_failed(&mut self, problem: String) {
        if let Some(form) = &mut self.add_survey {
            form.error = Some(problem.clone());
        }
        self.log_line(format!("the survey was not added: {problem}"));
    }
}
