//! Refining the selection from the viewer: the refinement job (`damage::refine`, with the
//! person's selection instead of a mask-based one) on a worker, its progress and improving model
//! streamed into the viewport, cancel; the result becomes the model on screen and undo brings the
//! previous one back.

use std::sync::Arc;
use std::time::Duration;

use crossbeam_channel::TryRecvError;

use super::AppState;
use crate::damage::refine::{RefineConfig, RefineOutcome, Strategy, refine_job};
use crate::splats::Splats;
use crate::splats::selection::{Edit, selected_count};
use crate::train::job::{Job, JobEvent, JobOptions, Progress};

/// A refinement running on the selection.
pub struct RefineSession {
    job: Job<RefineOutcome>,
    /// The model before it, for undo.
    previous: Arc<Splats>,
    pub progress: Option<Progress>,
}

impl AppState {
    pub(super) fn start_refine(&mut self, strategy: Strategy, iterations: u32) {
        if self.refine.is_some() || self.training.as_ref().is_some_and(|t| t.is_running()) {
            self.log_line("a refinement or training is running: wait for it or stop it");
            return;
        }
        let (Some(splats), Some(dataset)) = (
            self.splats.clone(),
            self.scene.as_ref().and_then(|s| s.dataset.clone()),
        ) else {
            self.log_line("refining needs a model and its dataset (open a project)");
            return;
        };
        if selected_count(&splats) == 0 {
            self.log_line("nothing selected to refine");
            return;
        }
        let given: Vec<u32> = (0..splats.len() as u32)
            .filter(|&g| splats.meta.state[g as usize] & crate::splats::model::state::SELECTED != 0)
            .collect();
        self.log_line(format!(
            "refining {} selected Gaussians ({strategy:?}, {iterations} steps)",
            given.len()
        ));
        let config = RefineConfig {
            strategy,
            iterations,
            given: Some(given),
            // A hardware GPU when there is one, as live training.
            backend: crate::train::backend_choice::Backend::Auto,
            ..RefineConfig::default()
        };
        let options = JobOptions {
            snapshot_interval: Some(Duration::from_millis(500)),
            low_priority: true,
            ..JobOptions::default()
        };
        let job = refine_job(dataset, splats.clone(), config, options);
        self.refine = Some(RefineSession {
            job,
            previous: splats,
            progress: None,
        });
    }

    pub(super) fn cancel_refine(&mut self) {
        if let Some(session) = &self.refine {
            session.job.cancel();
            self.log_line("cancelling the refinement");
        }
    }

    /// Drains the refinement's events; true when anything changed.
    pub(super) fn poll_refine(&mut self) -> bool {
        let mut changed = false;
        loop {
            let Some(session) = &mut self.refine else {
                return changed;
            };
            let event = match session.job.events().try_recv() {
                Ok(event) => event,
                Err(TryRecvError::Empty) => return changed,
                Err(TryRecvError::Disconnected) => {
                    self.refine = None;
                    self.log_line("the refinement worker stopped");
                    return true;
                }
            };
            changed = true;
            match event {
                JobEvent::Progress(p) => session.progress = Some(p),
                JobEvent::Log(line) => self.log_line(format!("refine: {line}")),
                JobEvent::NanRolledBack { step, reason } => {
                    self.log_line(format!("refine: step {step} rolled back ({reason})"));
                }
                // The improving model, shown but not yet the model (undo stays as it was).
                JobEvent::Snapshot(model) => self.show_edited(model),
                JobEvent::Finished(outcome) => self.finish_refine(outcome),
                JobEvent::Failed(error) => {
                    let previous = self.refine.take().map(|s| s.previous);
                    if let Some(p) = previous {
                        self.show_edited(p);
                    }
                    self.log_line(format!("refinement failed: {error}"));
                }
            }
        }
    }

    fn finish_refine(&mut self, outcome: RefineOutcome) {
        let Some(session) = self.refine.take() else {
            return;
        };
        if outcome.cancelled {
            self.show_edited(session.previous);
            self.log_line("refinement cancelled: the model is as it was");
            return;
        }
        let r = &outcome.report;
        let iou = |q: &crate::damage::refine::Quality| {
            q.iou
                .iter()
                .map(|(k, v)| format!("{k} {v:.3}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        self.log_line(format!(
            "refined in {:.0} s: held-out IoU {} before, {} after",
            r.seconds.total,
            iou(&r.before),
            iou(&r.after)
        ));
        // Undo swaps the previous model back in.
        self.edits
            .push(Edit::Model(Box::new(Splats::clone(&session.previous))));
        self.show_edited(outcome.splats);
    }
}
