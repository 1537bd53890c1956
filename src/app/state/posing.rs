//! "New twin from photos…" in the viewer: the dialog's fields kept in the state (a file dialog
//! fills the photos folder from its worker), COLMAP run by `timeline::from_photos`'s job on a
//! worker (the same run as `damage-twin pose`), its stages as progress, Cancel killing COLMAP
//! with nothing written, and once done the new project opened (and trained, when asked). The
//! dialog stays open with the refusal line when no twin was made. Also where a COLMAP run's log
//! is: the staging folder's while it runs, the dataset's once done, the kept copy after a failure.

use std::path::{Path, PathBuf};

use super::AppState;
use super::saving::viewer_writer;
use crate::app::commands::Command;
use crate::app::twin_form::NewTwinForm;
use crate::scene::run_folder::staging_path;
use crate::scene::sfm::pose::LOG_FILE;
use crate::scene::sfm::workspace::failed_log_path;
use crate::timeline::from_photos::{PosedTwin, new_twin_from_photos_job};
use crate::train::job::{Job, JobEvent, JobOptions, Progress};

/// The "New twin from photos…" dialog while it is open.
pub struct NewTwinDialog {
    pub form: NewTwinForm,
    pub run: Option<PoseRun>,
    /// The dataset folder of the last run, whose COLMAP log the dialog offers.
    pub last_dataset: Option<PathBuf>,
}

/// COLMAP posing the photos.
pub struct PoseRun {
    pub job: Job<Option<PosedTwin>>,
    pub progress: Option<Progress>,
}

/// The log of the COLMAP run writing `dataset`: the running job's (in its staging folder), the
/// dataset's own once it is written, or the copy a failed run kept beside it; `None` when there
/// is none (never run, or cancelled).
pub fn colmap_log_of(dataset: &Path) -> Option<PathBuf> {
    let live = match (dataset.parent(), dataset.file_name()) {
        (Some(parent), Some(name)) => {
            let parent = match parent.as_os_str().is_empty() {
                true => Path::new("."),
                false => parent,
            };
            Some(staging_path(parent, &name.to_string_lossy()).join(LOG_FILE))
        }
        _ => None,
    };
    live.into_iter()
        .chain([dataset.join(LOG_FILE), failed_log_path(dataset)])
        .find(|p| p.is_file())
}

impl AppState {
    pub(super) fn open_new_twin(&mut self) {
        if self.new_twin.is_none() {
            self.new_twin = Some(NewTwinDialog {
                form: NewTwinForm::default(),
                run: None,
                last_dataset: None,
            });
        }
    }

    /// The panel's edited fields; a change of any field clears the last refusal.
    pub(super) fn edit_new_twin(&mut self, form: NewTwinForm) {
        if let Some(dialog) = &mut self.new_twin {
            let changed = !dialog.form.same_inputs(&form);
            dialog.form = form;
            if changed {
                dialog.form.error = None;
            }
        }
    }

    pub(super) fn choose_twin_photos(&mut self, folder: PathBuf) {
        if let Some(dialog) = &mut self.new_twin {
            dialog.form.choose_photos(&folder);
            dialog.form.error = None;
        }
    }

    /// Starts posing the photos the dialog names; a form that names none gets its error line.
    pub(super) fn start_new_twin(&mut self) {
        let Some(dialog) = &mut self.new_twin else {
            return;
        };
        if dialog.run.is_some() {
            return;
        }
        let request = match dialog.form.request(viewer_writer(true)) {
            Ok(request) => request,
            Err(problem) => {
                dialog.form.error = Some(problem.clone());
                self.log_line(format!("cannot make the twin: {problem}"));
                return;
            }
        };
        dialog.form.error = None;
        dialog.last_dataset = Some(request.dataset.clone());
        let line = format!(
            "posing the photos in {} with COLMAP",
            request.photos.display()
        );
        let job = new_twin_from_photos_job(
            request,
            JobOptions {
                low_priority: true,
                ..JobOptions::default()
            },
        );
        dialog.run = Some(PoseRun {
            job,
            progress: None,
        });
        self.log_line(line);
    }

    pub(super) fn cancel_new_twin(&mut self) {
        if let Some(run) = self.new_twin.as_ref().and_then(|d| d.run.as_ref()) {
            run.job.cancel();
            self.log_line("cancelling: posing the photos");
        }
    }

    /// Closes the dialog (a run still going is cancelled: its handle's drop waits for it).
    pub(super) fn close_new_twin(&mut self) {
        if let Some(run) = self.new_twin.take().and_then(|d| d.run) {
            run.job.cancel();
        }
    }

    /// Drains the posing job's events; true when anything changed.
    pub(super) fn poll_new_twin(&mut self) -> bool {
        let mut changed = false;
        loop {
            let Some(run) = self.new_twin.as_mut().and_then(|d| d.run.as_mut()) else {
                return changed;
            };
            let Ok(event) = run.job.events().try_recv() else {
                return changed;
            };
            changed = true;
            match event {
                JobEvent::Progress(p) => run.progress = Some(p),
                JobEvent::Log(line) => self.log_line(line),
                JobEvent::Snapshot(_) | JobEvent::NanRolledBack { .. } => {}
                JobEvent::Finished(Some(posed)) => self.finish_new_twin(posed),
                JobEvent::Finished(None) => self.new_twin_failed(
                    "cancelled: COLMAP was stopped, and no dataset or project was written".into(),
                ),
                JobEvent::Failed(error) => self.new_twin_failed(error.to_string()),
            }
        }
    }

    fn new_twin_failed(&mut self, problem: String) {
        if let Some(dialog) = &mut self.new_twin {
            dialog.run = None;
            dialog.form.error = Some(problem.clone());
        }
        self.log_line(format!("no twin was made: {problem}"));
    }

    /// The project made: the dialog closed, the project opened (and trained when asked).
    fn finish_new_twin(&mut self, posed: PosedTwin) {
        let train = self.new_twin.take().is_some_and(|d| d.form.train);
        let s = &posed.summary;
        self.log_line(format!(
            "posed {} of {} photos ({} matching, {}) in {:.0} s: {} points, mean reprojection \
             error {:.2} px",
            s.registered.len(),
            s.photos,
            s.matching.name(),
            s.engine,
            s.seconds,
            s.points,
            s.mean_reprojection_error_px
        ));
        if !s.unregistered.is_empty() {
            self.log_line(format!(
                "not registered (left out of the dataset): {}",
                s.unregistered.join(", ")
            ));
        }
        match (&s.georeference, &s.georeference_note) {
            (Some(g), _) => self.log_line(format!(
                "georeferenced from {:?}: {:.4} m per unit, residual {:.2} m RMS",
                g.source,
                g.metres_per_unit(),
                g.rms_m
            )),
            (None, Some(note)) => self.log_line(format!("no georeference: {note}")),
            (None, None) => {}
        }
        for warning in &s.warnings {
            self.log_line(format!("warning: {warning}"));
        }
        let dir = posed.twin.dir().to_path_buf();
        self.log_line(format!("created the twin {}", dir.display()));
        self.train_on_open = train;
        self.apply(Command::Open(dir));
    }
}
