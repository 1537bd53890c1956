//! The viewer's side of one training run: starts a `TrainJob` (setup and training on the worker),
//! drains its events with `try_recv` only (the UI never waits on the trainer), and keeps the
//! latest progress for the panels. No training algorithm here: see `train::job`.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crossbeam_channel::TryRecvError;

use crate::damage::setup::{RunConfig, TrainingSettings, train_job};
use crate::scene::Dataset;
use crate::splats::Splats;
use crate::train::backend_choice::Backend;
use crate::train::history::History;
use crate::train::job::{JobEvent, JobOptions, Progress};
use crate::train::run::{TrainJob, TrainOutcome};

/// At most this many events are handled per frame, so a flood cannot stall a frame; the rest
/// wait for the next one.
const EVENTS_PER_POLL: usize = 2000;

/// Where a run stands.
#[derive(Clone, Debug, PartialEq)]
pub enum RunStatus {
    /// Loading views and initialising on the worker.
    Preparing,
    Running,
    Paused,
    /// Stop was asked; the worker finishes its current step.
    Stopping,
    Finished {
        cancelled: bool,
        heldout_psnr: Option<f64>,
        seconds: f64,
    },
    Failed(String),
}

/// What one `poll` brought.
#[derive(Default)]
pub struct PollUpdate {
    pub changed: bool,
    pub snapshot: Option<Arc<Splats>>,
    pub log: Vec<String>,
}

/// One training run as the viewer sees it.
pub struct TrainingSession {
    job: Option<TrainJob>,
    pub status: RunStatus,
    pub progress: Option<Progress>,
    pub settings: TrainingSettings,
    /// Latest held-out PSNR reported during the run.
    pub heldout_psnr: Option<f64>,
    pub outcome: Option<TrainOutcome>,
    started: Instant,
}

impl TrainingSession {
    /// Starts training `dataset` on a worker thread; returns at once.
    pub fn start(
        dataset: Arc<Dataset>,
        settings: TrainingSettings,
        palette: crate::damage::Palette,
        background: [f32; 3],
    ) -> TrainingSession {
        let options = JobOptions {
            // Leave a core for the UI: on this 2-core machine the viewer must stay fluid.
            threads: Some(
                std::thread::available_parallelism()
                    .map(|n| n.get().saturating_sub(1).max(1))
                    .unwrap_or(1),
            ),
            snapshot_interval: Some(Duration::from_millis(250)),
            // Frames first: the viewport's renders (on a software driver, CPU threads too)
            // must not wait for a training step.
            low_priority: true,
        };
        let config = RunConfig {
            // Train on a hardware GPU when there is one (a software driver stays slower than
            // the CPU rasterizer).
            backend: Backend::Auto,
            ..RunConfig::interactive(&settings, palette, background)
        };
        let job = train_job(dataset, config, options);
        TrainingSession {
            job: Some(job),
            status: RunStatus::Preparing,
            progress: None,
            settings,
            heldout_psnr: None,
            outcome: None,
            started: Instant::now(),
        }
    }

    /// True while the run is training, so new models keep arriving (not preparing, paused,
    /// finished or failed).
    pub fn is_streaming(&self) -> bool {
        matches!(self.status, RunStatus::Running | RunStatus::Stopping)
    }

    /// True until the run has finished or failed.
    pub fn is_running(&self) -> bool {
        !matches!(
            self.status,
            RunStatus::Finished { .. } | RunStatus::Failed(_)
        )
    }

    pub fn pause(&mut self) {
        if let Some(job) = &self.job
            && matches!(self.status, RunStatus::Running | RunStatus::Preparing)
        {
            job.pause();
            self.status = RunStatus::Paused;
        }
    }

    pub fn resume(&mut self) {
        if let Some(job) = &self.job
            && self.status == RunStatus::Paused
        {
            job.resume();
            self.status = RunStatus::Running;
        }
    }

    /// Asks the worker to stop after its current step; the final snapshot still arrives.
    pub fn stop(&mut self) {
        if let Some(job) = &self.job
            && self.is_running()
        {
            // A paused worker blocks on the control channel; cancel wakes it.
            job.cancel();
            self.status = RunStatus::Stopping;
        }
    }

    /// Cancels without waiting: the worker is joined on a detached thread, so dropping a session
    /// never blocks the UI for the length of a training step.
    pub fn cancel(mut self) {
        if let Some(job) = self.job.take() {
            job.cancel();
            std::thread::spawn(move || drop(job));
        }
    }

    /// Fraction done in [0, 1].
    pub fn fraction(&self) -> f32 {
        match (&self.status, &self.progress) {
            (RunStatus::Finished { .. }, _) => 1.0,
            (_, Some(p)) if p.total > 0 => p.step as f32 / p.total as f32,
            _ => 0.0,
        }
    }

    /// Drains pending events without blocking.
    pub fn poll(&mut self, history: &mut History) -> PollUpdate {
        let mut update = PollUpdate::default();
        let Some(job) = &self.job else {
            return update;
        };
        for _ in 0..EVENTS_PER_POLL {
            let event = match job.events().try_recv() {
                Ok(event) => event,
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    if self.is_running() {
                        self.status = RunStatus::Failed("the training worker stopped".into());
                        update.changed = true;
                    }
                    break;
                }
            };
            update.changed = true;
            match event {
                JobEvent::Progress(p) => {
                    if self.status == RunStatus::Preparing {
                        self.status = RunStatus::Running;
                    }
                    history.record_progress(&p, self.started.elapsed().as_secs_f64());
                    if p.psnr.is_some() {
                        self.heldout_psnr = p.psnr;
                    }
                    self.progress = Some(p);
                }
                JobEvent::Snapshot(splats) => update.snapshot = Some(splats),
                JobEvent::Log(line) => update.log.push(line),
                JobEvent::NanRolledBack { step, reason } => {
                    update
                        .log
                        .push(format!("step {step} rolled back: {reason}"));
                }
                JobEvent::Finished(outcome) => {
                    let heldout_psnr = outcome.heldout.as_ref().map(|s| s.psnr);
                    if heldout_psnr.is_some() {
                        self.heldout_psnr = heldout_psnr;
                    }
                    history.record_final(heldout_psnr, self.started.elapsed().as_secs_f64());
                    update.log.push(format!(
                        "training {} after {} of {} steps in {:.1} s{}",
                        if outcome.cancelled {
                            "stopped"
                        } else {
                            "finished"
                        },
                        outcome.steps,
                        outcome.total,
                        outcome.seconds,
                        heldout_psnr
                            .map(|p| format!(", held-out PSNR {p:.2} dB"))
                            .unwrap_or_default()
                    ));
                    update.snapshot = Some(outcome.splats.clone());
                    self.status = RunStatus::Finished {
                        cancelled: outcome.cancelled,
                        heldout_psnr,
                        seconds: outcome.seconds,
                    };
                    self.outcome = Some(outcome);
                }
                JobEvent::Failed(e) => {
                    update.log.push(format!("training failed: {e}"));
                    self.status = RunStatus::Failed(e.to_string());
                }
            }
        }
        update
    }
}

impl Drop for TrainingSession {
    fn drop(&mut self) {
        if let Some(job) = self.job.take() {
            job.cancel();
            // Joining could take a whole training step; let a detached thread do it.
            std::thread::spawn(move || drop(job));
        }
    }
}
