//! The project's surveys in the viewer: stepping through them (each survey's model and photos;
//! the camera stays, so the same view compares), a second survey beside the one shown (side by
//! side or swipe, one camera for both), and the timeline's jobs, detect changes and update the
//! twin, running on workers with their progress and improving model streamed in. A survey
//! stepped away from keeps its edits until the project is saved.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use crossbeam_channel::{Sender, TryRecvError};

use super::ProjectWatch;
use super::saving::viewer_writer;
use super::{AppState, WorkerResult};
use crate::damage::layer::{DamageLayer, survey_colours};
use crate::damage::refine::Strategy;
use crate::scene::Dataset;
use crate::splats::Splats;
use crate::timeline::Twin;
use crate::timeline::add_survey::AddedSurvey;
use crate::timeline::detect_survey::{
    ChangeSummary, DetectOptions, change_map_path, compared_survey, detect_job,
};
use crate::timeline::update::{UpdateConfig, UpdateOutcome, update_project_job};
use crate::train::history::History;
use crate::train::job::{Job, JobEvent, JobOptions, Progress};

/// A survey loaded into the viewer.
#[derive(Clone, Debug)]
pub struct LoadedSurvey {
    /// Its model (None before one was trained or updated).
    pub splats: Option<Arc<Splats>>,
    /// Its dataset, placed in the twin's frame (None for a survey saved from a bare model).
    pub dataset: Option<Arc<Dataset>>,
    /// Edited in the viewer since it was loaded or saved.
    pub edited: bool,
}

/// A timeline job running.
pub enum TimelineWork {
    Detect(Job<(Twin, ChangeSummary)>),
    Update(Job<(Twin, UpdateOutcome)>),
    /// "Add survey…" (`adding_survey`); `survey` is the index it will take.
    AddSurvey(Job<(Twin, Option<AddedSurvey>)>),
}

pub struct TimelineJob {
    pub work: TimelineWork,
    /// The survey it works on.
    pub survey: usize,
    pub progress: Option<Progress>,
    /// The job's progress against wall time, kept with the updated survey for the report.
    pub history: History,
    pub started: std::time::Instant,
}

impl TimelineJob {
    pub fn cancel(&self) {
        match &self.work {
            TimelineWork::Detect(j) => j.cancel(),
            TimelineWork::Update(j) => j.cancel(),
            TimelineWork::AddSurvey(j) => j.cancel(),
        }
    }

    pub fn name(&self) -> &'static str {
        match self.work {
            TimelineWork::Detect(_) => "detecting changes",
            TimelineWork::Update(_) => "updating the twin",
            TimelineWork::AddSurvey(_) => "adding the survey",
        }
    }
}

/// The open project's timeline.
pub struct TimelineView {
    pub twin: Twin,
    /// The survey shown.
    pub current: usize,
    /// The survey shown beside it.
    pub compare: Option<usize>,
    /// Bumped whenever the compared model changes (the renderer re-uploads on change).
    pub compare_generation: u64,
    pub loaded: BTreeMap<usize, LoadedSurvey>,
    /// Surveys being read on a worker.
    pub loading: BTreeSet<usize>,
    /// The survey to show once it has loaded.
    pending_show: Option<usize>,
    pub job: Option<TimelineJob>,
    /// Snapping to a view shows the survey's change map instead of its photo, where one exists.
    pub show_change_maps: bool,
    /// Other processes writing the project, and its file's last change.
    pub watch: ProjectWatch,
    /// Its georeference and registrations, for the project panel (read by `poll`).
    pub records: Option<super::ProjectRecords>,
}

impl TimelineView {
    /// The timeline of `twin` showing survey `current` (already loaded).
    pub fn new(twin: Twin, current: usize, shown: LoadedSurvey) -> TimelineView {
        TimelineView {
            watch: ProjectWatch::new(&twin),
            twin,
            current,
            compare: None,
            compare_generation: 0,
            loaded: BTreeMap::from([(current, shown)]),
            loading: BTreeSet::new(),
            pending_show: None,
            job: None,
            show_change_maps: false,
            records: None,
        }
    }

    pub fn survey_name(&self, index: usize) -> Option<&str> {
        self.twin
            .project
            .surveys
            .get(index)
            .map(|s| s.name.as_str())
    }

    /// The compared survey's model, when one is chosen and loaded.
    pub fn compared(&self) -> Option<(usize, Arc<Splats>)> {
        let index = self.compare?;
        let splats = self.loaded.get(&index)?.splats.clone()?;
        Some((index, splats))
    }

    /// The damage layer for survey `index`'s picture: by survey, every survey before the later
    /// of the two on screen in the earlier-damage colour and that one's own in the new-damage
    /// colour, so both pictures colour the same damage alike.
    pub fn layer(&self, base: &DamageLayer, index: usize) -> DamageLayer {
        let latest = self.current.max(self.compare.unwrap_or(0));
        DamageLayer {
            survey_colours: survey_colours(latest, self.twin.project.settings.new_damage_colour),
            own_survey: index as u16,
            ..base.clone()
        }
    }

    /// The change map of view `view_name` of the survey shown, when changes were detected.
    pub fn change_map(&self, view_name: &str) -> Option<PathBuf> {
        let survey = self.twin.project.surveys.get(self.current)?;
        let folder = self.twin.inside(survey.changes.as_ref()?).ok()?;
        let path = change_map_path(&folder, view_name);
        // Anything there is the map: a folder or a pipe in its place is refused by the loader.
        crate::scene::files::is_present(&path).then_some(path)
    }
}

/// Survey `name`'s dataset in the twin's frame; None for a survey saved from a bare model.
pub fn survey_dataset(
    twin: &Twin,
    name: &str,
) -> Result<Option<Arc<Dataset>>, crate::timeline::TimelineError> {
    if twin.survey(name)?.dataset.as_os_str().is_empty() {
        return Ok(None);
    }
    Ok(Some(Arc::new(twin.open_survey_dataset(name)?)))
}

/// Reads survey `index` of `twin` (its model and its dataset in the twin's frame) on a worker.
fn load_survey(twin: Twin, index: usize, results: Sender<WorkerResult>) {
    let spawned = std::thread::Builder::new()
        .name("damage-twin-survey".into())
        .spawn(move || {
            let result = (|| {
                let name = twin.project.surveys[index].name.clone();
                let dataset = survey_dataset(&twin, &name)?;
                let splats = twin.load_model(&name)?;
                Ok::<_, crate::timeline::TimelineError>(LoadedSurvey {
                    splats: splats.map(Arc::new),
                    dataset,
                    edited: false,
                })
            })()
            .map_err(|e| e.to_string());
            let _ = results.send(WorkerResult::SurveyLoaded { index, result });
        });
    if let Err(e) = spawned {
        tracing::error!("cannot start a survey loading thread: {e}");
    }
}

impl AppState {
    /// Shows survey `index` (loading it first when needed).
    pub(super) fn show_survey(&mut self, index: usize) {
        let busy = self.training.as_ref().is_some_and(|t| t.is_running()) || self.refine.is_some();
        let Some(timeline) = &mut self.timeline else {
            self.log_line("open a twin project to step through its surveys");
            return;
        };
        if index >= timeline.twin.project.surveys.len() || index == timeline.current {
            return;
        }
        if busy {
            self.log_line("training or a refinement is running: stop it before changing survey");
            return;
        }
        if timeline.loaded.contains_key(&index) {
            self.show_loaded_survey(index);
        } else {
            timeline.pending_show = Some(index);
            if timeline.loading.insert(index) {
                load_survey(timeline.twin.clone(), index, self.results_sender());
            }
        }
    }

    fn show_loaded_survey(&mut self, index: usize) {
        let edited = self.edits.can_undo();
        let (splats, dataset) = (self.splats.clone(), self.scene_dataset());
        let Some(timeline) = &mut self.timeline else {
            return;
        };
        // The survey stepped away from keeps its model as edited here.
        if let Some(slot) = timeline.loaded.get_mut(&timeline.current) {
            slot.splats = splats;
            slot.edited |= edited;
            slot.dataset = dataset;
        }
        let Some(shown) = timeline.loaded.get(&index).cloned() else {
            return;
        };
        let previous = timeline.current;
        timeline.current = index;
        timeline.pending_show = None;
        if timeline.compare == Some(index) {
            // Comparing a survey with itself says nothing: the two swap places.
            timeline.compare = Some(previous);
            timeline.compare_generation += 1;
        }
        let name = timeline.survey_name(index).unwrap_or_default().to_string();
        self.snap = None;
        self.regions = None;
        if let Some(scene) = &mut self.scene {
            scene.dataset = shown.dataset.clone();
        }
        match shown.splats {
            Some(s) => self.set_splats(s),
            None => {
                self.edits.clear();
                self.splats = None;
                self.splats_generation += 1;
                self.log_line(format!("survey {name} has no model yet: update the twin"));
            }
        }
        self.log_line(format!("showing survey {name}"));
    }

    fn scene_dataset(&self) -> Option<Arc<Dataset>> {
        self.scene.as_ref().and_then(|s| s.dataset.clone())
    }

    /// Shows survey `index` beside the one shown (None: only the one shown).
    pub(super) fn compare_survey(&mut self, index: Option<usize>) {
        let results = self.results_sender();
        let Some(timeline) = &mut self.timeline else {
            return;
        };
        let index = index.filter(|&i| i < timeline.twin.project.surveys.len());
        timeline.compare = index.filter(|&i| i != timeline.current);
        timeline.compare_generation += 1;
        if let Some(i) = timeline.compare
            && !timeline.loaded.contains_key(&i)
            && timeline.loading.insert(i)
        {
            load_survey(timeline.twin.clone(), i, results);
        }
    }

    pub(super) fn on_survey_loaded(&mut self, index: usize, result: Result<LoadedSurvey, String>) {
        let Some(timeline) = &mut self.timeline else {
            return;
        };
        timeline.loading.remove(&index);
        match result {
            Ok(loaded) => {
                timeline.loaded.insert(index, loaded);
                if timeline.compare == Some(index) {
                    timeline.compare_generation += 1;
                }
                if timeline.pending_show == Some(index) {
                    self.show_loaded_survey(index);
                }
            }
            Err(e) => {
                if timeline.pending_show == Some(index) {
                    timeline.pending_show = None;
                }
                if timeline.compare == Some(index) {
                    timeline.compare = None;
                }
                self.log_line(format!("error: {e}"));
            }
        }
    }

    pub(super) fn timeline_job_refused(&mut self) -> bool {
        let busy = self.training.as_ref().is_some_and(|t| t.is_running()) || self.refine.is_some();
        let running = self.timeline.as_ref().is_some_and(|t| t.job.is_some());
        if busy || running {
            self.log_line("another job is running: wait for it or stop it");
        }
        busy || running
    }

    /// Finds the shown survey's new damage against the twin before it.
    pub(super) fn detect_changes(&mut self) {
        if self.timeline_job_refused() {
            return;
        }
        let Some(timeline) = &mut self.timeline else {
            self.log_line("open a twin project with two surveys to detect changes");
            return;
        };
        let survey = timeline.current;
        let name = timeline.survey_name(survey).unwrap_or_default().to_string();
        let Some(previous) = compared_survey(&timeline.twin, survey) else {
            self.log_line(format!(
                "no survey before {name} has a model to compare with"
            ));
            return;
        };
        let job = detect_job(
            timeline.twin.clone().with_writer(viewer_writer(true)),
            name.clone(),
            DetectOptions {
                scale: timeline.twin.project.settings.scale,
                ..DetectOptions::default()
            },
            JobOptions {
                low_priority: true,
                ..JobOptions::default()
            },
        );
        timeline.job = Some(TimelineJob {
            work: TimelineWork::Detect(job),
            survey,
            progress: None,
            history: History::default(),
            started: std::time::Instant::now(),
        });
        self.log_line(format!(
            "detecting the changes of {name} against the twin of {previous}"
        ));
    }

    /// Updates the shown survey's model from the survey before it with its photos and masks.
    pub(super) fn update_twin(&mut self, strategy: Strategy, iterations: u32) {
        if self.timeline_job_refused() {
            return;
        }
        let Some(timeline) = &mut self.timeline else {
            self.log_line("open a twin project with two surveys to update the twin");
            return;
        };
        let survey = timeline.current;
        let name = timeline.survey_name(survey).unwrap_or_default().to_string();
        if survey == 0 {
            self.log_line(format!(
                "{name} is the first survey: there is no earlier twin to update"
            ));
            return;
        }
        let unsaved = timeline.loaded.get(&(survey - 1)).is_some_and(|s| s.edited);
        let mut config = UpdateConfig::for_project(
            &timeline.twin,
            strategy,
            timeline.twin.project.settings.scale,
            Some(iterations),
            true,
        );
        // A hardware GPU when there is one, as live training.
        config.refine.backend = crate::train::backend_choice::Backend::Auto;
        let options = JobOptions {
            snapshot_interval: Some(Duration::from_millis(500)),
            low_priority: true,
            ..JobOptions::default()
        };
        let twin = timeline.twin.clone().with_writer(viewer_writer(true));
        let job = update_project_job(twin, name.clone(), config, options);
        timeline.job = Some(TimelineJob {
            work: TimelineWork::Update(job),
            survey,
            progress: None,
            history: History::default(),
            started: std::time::Instant::now(),
        });
        if unsaved {
            self.log_line("note: the update starts from the earlier survey's saved model, not its unsaved edits");
        }
        self.log_line(format!(
            "updating the twin with {name} ({strategy:?}, {iterations} steps)"
        ));
    }

    pub(super) fn cancel_timeline_job(&mut self) {
        if let Some(job) = self.timeline.as_ref().and_then(|t| t.job.as_ref()) {
            job.cancel();
            self.log_line(format!("cancelling: {}", job.name()));
        }
    }

    /// Drains the timeline job's events; true when anything changed.
    pub(super) fn poll_timeline(&mut self) -> bool {
        let mut changed = false;
        loop {
            let Some(job) = self.timeline.as_mut().and_then(|t| t.job.as_mut()) else {
                return changed;
            };
            let survey = job.survey;
            let event = match &job.work {
                TimelineWork::Detect(j) => j
                    .events()
                    .try_recv()
                    .map(|e| e.map(|r| Done::Detect(Box::new(r)))),
                TimelineWork::Update(j) => j
                    .events()
                    .try_recv()
                    .map(|e| e.map(|r| Done::Update(Box::new(r)))),
                TimelineWork::AddSurvey(j) => j
                    .events()
                    .try_recv()
                    .map(|e| e.map(|r| Done::AddSurvey(Box::new(r)))),
            };
            let event = match event {
                Ok(event) => event,
                Err(TryRecvError::Empty) => return changed,
                Err(TryRecvError::Disconnected) => {
                    self.end_timeline_job();
                    self.log_line("the timeline worker stopped");
                    return true;
                }
            };
            changed = true;
            match event {
                JobEvent::Progress(p) => {
                    job.history
                        .record_progress(&p, job.started.elapsed().as_secs_f64());
                    job.progress = Some(p);
                }
                JobEvent::Log(line) => {
                    let name = job.name();
                    self.log_line(format!("{name}: {line}"));
                }
                JobEvent::NanRolledBack { step, reason } => {
                    self.log_line(format!("update: step {step} rolled back ({reason})"));
                }
                JobEvent::Snapshot(model) => {
                    if self.timeline.as_ref().is_some_and(|t| t.current == survey) {
                        self.show_edited(model);
                    }
                }
                JobEvent::Finished(done) => {
                    self.end_timeline_job();
                    self.finish_timeline_job(survey, done);
                }
                JobEvent::Failed(error) => {
                    let adding = matches!(job.work, TimelineWork::AddSurvey(_));
                    self.end_timeline_job();
                    self.log_line(format!("failed: {error}"));
                    if adding {
                        self.add_survey_failed(error.to_string());
                    } else {
                        self.restore_shown_survey(survey);
                    }
                }
            }
        }
    }

    fn end_timeline_job(&mut self) {
        if let Some(t) = &mut self.timeline {
            t.job = None;
        }
    }

    /// After a failed or cancelled update, the survey's model as it was before.
    fn restore_shown_survey(&mut self, survey: usize) {
        let model = self.timeline.as_ref().and_then(|t| {
            (t.current == survey)
                .then(|| t.loaded.get(&survey).and_then(|s| s.splats.clone()))
                .flatten()
        });
        if let Some(model) = model {
            self.show_edited(model);
        }
    }

    /// A finished job's result shown; the job itself committed it (an update with its training
    /// history, `update_project_job`).
    fn finish_timeline_job(&mut self, survey: usize, done: Done) {
        match done {
            Done::AddSurvey(done) => self.finish_add_survey(*done),
            Done::Detect(done) => {
                let (twin, summary) = *done;
                let figures = summary
                    .new_damage
                    .iter()
                    .map(|(class, f)| match f.recall {
                        Some(r) => format!("{class} {} px (recall {r:.2})", f.pixels),
                        None => format!("{class} {} px", f.pixels),
                    })
                    .collect::<Vec<_>>()
                    .join(", ");
                if let Some(t) = &mut self.timeline {
                    t.twin = twin;
                    t.show_change_maps = true;
                }
                self.log_line(format!(
                    "changes of {} against {}: new {figures}; change maps in {} (snap to a view to see them)",
                    summary.survey,
                    summary.twin_of,
                    summary.folder.display()
                ));
                if let Some(view) = self.snap.as_ref().map(|s| s.view) {
                    self.snap_to(view);
                }
            }
            Done::Update(done) => {
                let (twin, outcome) = *done;
                if outcome.cancelled {
                    self.log_line("update cancelled: nothing was written");
                    self.restore_shown_survey(survey);
                    return;
                }
                let r = &outcome.report;
                self.log_line(format!(
                    "updated {} from {} in {:.0} s: {} new-damage Gaussians, {} old",
                    r.survey, r.previous, r.seconds, r.new_damage_gaussians, r.old_damage_gaussians
                ));
                let model = Arc::new(outcome.splats);
                let Some(t) = &mut self.timeline else {
                    return;
                };
                t.twin = twin;
                if let Some(slot) = t.loaded.get_mut(&survey) {
                    slot.splats = Some(model.clone());
                    slot.edited = false;
                }
                if t.compare == Some(survey) {
                    t.compare_generation += 1;
                }
                if t.current == survey {
                    self.set_splats(model);
                }
            }
        }
    }
}

/// A finished timeline job's result.
pub(super) enum Done {
    Detect(Box<(Twin, ChangeSummary)>),
    Update(Box<(Twin, UpdateOutcome)>),
    AddSurvey(Box<(Twin, Option<AddedSurvey>)>),
}

/// A `JobEvent` of one result type mapped to another.
trait MapEvent<R> {
    fn map<S>(self, f: impl FnOnce(R) -> S) -> JobEvent<S>;
}

impl<R> MapEvent<R> for JobEvent<R> {
    fn map<S>(self, f: impl FnOnce(R) -> S) -> JobEvent<S> {
        match self {
            JobEvent::Progress(p) => JobEvent::Progress(p),
            JobEvent::Snapshot(s) => JobEvent::Snapshot(s),
            JobEvent::Log(l) => JobEvent::Log(l),
            JobEvent::NanRolledBack { step, reason } => JobEvent::NanRolledBack { step, reason },
            JobEvent::Finished(r) => JobEvent::Finished(f(r)),
            JobEvent::Failed(e) => JobEvent::Failed(e),
        }
    }
}
