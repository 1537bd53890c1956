//! The job API (DESIGN.md): a training run on a worker thread that reports progress, `Arc`
//! snapshots, log lines and one final result over a crossbeam channel, and obeys pause / resume /
//! cancel sent the other way. The app and the CLI are clients of this; no algorithm lives here.

use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender, TryRecvError};

use crate::splats::Splats;
use crate::train::evaluate::EvalScores;
use crate::train::priority;
use crate::train::spec::{TrainSpec, TrainView};
use crate::train::trainer::{StageTimes, Trainer};

/// One progress report, sent after every step.
#[derive(Clone, Debug)]
pub struct Progress {
    /// Steps done so far (1-based after the first step).
    pub step: u32,
    pub total: u32,
    /// Loss of the last step (NaN when the step was rolled back).
    pub loss: f32,
    /// Held-out PSNR, present on the steps where the held-out views were evaluated.
    pub psnr: Option<f64>,
    pub gaussians: usize,
    /// Training time, pauses excluded.
    pub elapsed: Duration,
    /// Remaining time at the current rate.
    pub eta: Duration,
}

/// What a finished (or cancelled) run leaves.
#[derive(Clone, Debug)]
pub struct TrainOutcome {
    pub splats: Arc<Splats>,
    pub steps: u32,
    pub total: u32,
    pub cancelled: bool,
    /// Training time, pauses excluded, held-out evaluations included.
    pub seconds: f64,
    /// Held-out scores of the final model (None when no held-out views were given).
    pub heldout: Option<EvalScores>,
    /// Steps whose NaN/Inf was rolled back.
    pub rolled_back: u32,
    /// Accumulated time per stage over the run.
    pub timings: StageTimes,
}

/// Events from the worker, in order; `Finished` or `Failed` is always the last one.
#[derive(Clone, Debug)]
pub enum JobEvent {
    Progress(Progress),
    /// The current model, at most every `JobOptions::snapshot_interval` and once at the end.
    Snapshot(Arc<Splats>),
    Log(String),
    /// A step produced NaN or Inf and was undone; training continues.
    NanRolledBack {
        step: u32,
        reason: String,
    },
    Finished(TrainOutcome),
    Failed(String),
}

/// Control messages from the client.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    Pause,
    Resume,
    Cancel,
}

/// What the worker trains: built on the worker thread by the setup closure (so that loading a
/// dataset does not block the caller).
pub struct TrainSetup {
    pub spec: TrainSpec,
    pub splats: Splats,
    pub views: Vec<TrainView>,
    /// Held-out views for PSNR during and after training (may be empty).
    pub heldout: Vec<TrainView>,
}

/// How the job runs (not what it trains).
#[derive(Clone, Copy, Debug)]
pub struct JobOptions {
    /// Rayon threads for this job; `None` uses the global pool.
    pub threads: Option<usize>,
    /// Minimum time between snapshots (DESIGN.md: at most ~10 per second); `None` sends only the
    /// final one (the CLI, which draws no splats).
    pub snapshot_interval: Option<Duration>,
    /// Run the worker and its rayon threads at a lower scheduling priority
    /// (`train::priority`): the viewer's frames come first, training takes the rest.
    pub low_priority: bool,
}

impl Default for JobOptions {
    fn default() -> Self {
        JobOptions {
            threads: None,
            snapshot_interval: Some(Duration::from_millis(100)),
            low_priority: false,
        }
    }
}

/// A running training job. Dropping the handle cancels the job and waits for the worker.
pub struct TrainJob {
    events: Receiver<JobEvent>,
    control: Sender<Control>,
    worker: Option<JoinHandle<()>>,
}

impl TrainJob {
    /// Starts a job from what is already in memory.
    pub fn spawn(setup: TrainSetup, options: JobOptions) -> TrainJob {
        TrainJob::spawn_with(move |_log| Ok(setup), options)
    }

    /// Starts a job whose inputs are produced on the worker by `setup` (dataset loading,
    /// initialisation); `setup` may send log lines through the given sender. An `Err` from it
    /// ends the job with `Failed`.
    pub fn spawn_with<F>(setup: F, options: JobOptions) -> TrainJob
    where
        F: FnOnce(&Sender<JobEvent>) -> Result<TrainSetup, String> + Send + 'static,
    {
        let (event_tx, events) = crossbeam_channel::unbounded();
        let (control, control_rx) = crossbeam_channel::unbounded();
        let worker = std::thread::Builder::new()
            .name("damage-twin-train".into())
            .spawn(move || {
                if options.low_priority {
                    priority::lower_current_thread_priority();
                }
                let body = || run_worker(setup, options, &event_tx, &control_rx);
                // Always inside a pool of our own, even at the default size: started from this
                // plain thread, every parallel loop of a step (~25) would hand its work to the
                // global pool and sleep until it came back, two wake-ups per loop (3-7 % of
                // user CPU per step at one thread on fox_bench_ds8, and 6x the system time).
                // A low-priority job's pool threads are lowered as they start.
                let threads = options.threads.unwrap_or(0);
                let mut pool = rayon::ThreadPoolBuilder::new().num_threads(threads);
                if options.low_priority {
                    pool = pool.start_handler(|_| priority::lower_current_thread_priority());
                }
                let result = match pool.build() {
                    Ok(pool) => pool.install(body),
                    Err(e) => Err(format!("cannot start the training threads: {e}")),
                };
                let last = match result {
                    Ok(outcome) => JobEvent::Finished(outcome),
                    Err(e) => JobEvent::Failed(e),
                };
                // The receiver may be gone (client dropped); nothing to report to then.
                let _ = event_tx.send(last);
            });
        let worker = match worker {
            Ok(handle) => Some(handle),
            Err(e) => {
                // No thread: report the failure through the channel like any other.
                let (tx, rx) = crossbeam_channel::unbounded();
                let _ = tx.send(JobEvent::Failed(format!(
                    "cannot start the training thread: {e}"
                )));
                return TrainJob {
                    events: rx,
                    control,
                    worker: None,
                };
            }
        };
        TrainJob {
            events,
            control,
            worker,
        }
    }

    /// The event stream; ends after `Finished` or `Failed`.
    pub fn events(&self) -> &Receiver<JobEvent> {
        &self.events
    }

    pub fn pause(&self) {
        let _ = self.control.send(Control::Pause);
    }

    pub fn resume(&self) {
        let _ = self.control.send(Control::Resume);
    }

    pub fn cancel(&self) {
        let _ = self.control.send(Control::Cancel);
    }

    /// True once the worker thread has ended.
    pub fn is_finished(&self) -> bool {
        self.worker.as_ref().is_none_or(|w| w.is_finished())
    }

    /// Blocks until the job ends and returns its final event's payload, draining the rest.
    pub fn wait(mut self) -> Result<TrainOutcome, String> {
        let mut last = Err("the training job ended without a result".to_string());
        for event in self.events.iter() {
            match event {
                JobEvent::Finished(outcome) => last = Ok(outcome),
                JobEvent::Failed(e) => last = Err(e),
                _ => {}
            }
        }
        if let Some(worker) = self.worker.take()
            && worker.join().is_err()
        {
            return Err("the training thread panicked".into());
        }
        last
    }
}

impl Drop for TrainJob {
    fn drop(&mut self) {
        if let Some(worker) = self.worker.take() {
            let _ = self.control.send(Control::Cancel);
            let _ = worker.join();
        }
    }
}

/// Applies pending control messages; blocks while paused. Returns true when cancelled.
fn handle_control(control: &Receiver<Control>, paused_since: &mut Option<Instant>) -> bool {
    loop {
        let message = if paused_since.is_some() {
            match control.recv() {
                Ok(m) => m,
                // Client gone while paused: nobody can resume, so stop.
                Err(_) => return true,
            }
        } else {
            match control.try_recv() {
                Ok(m) => m,
                Err(TryRecvError::Empty) | Err(TryRecvError::Disconnected) => return false,
            }
        };
        match message {
            Control::Cancel => return true,
            Control::Pause => {
                if paused_since.is_none() {
                    *paused_since = Some(Instant::now());
                }
            }
            Control::Resume => {
                *paused_since = None;
            }
        }
    }
}

fn run_worker<F>(
    setup: F,
    options: JobOptions,
    events: &Sender<JobEvent>,
    control: &Receiver<Control>,
) -> Result<TrainOutcome, String>
where
    F: FnOnce(&Sender<JobEvent>) -> Result<TrainSetup, String>,
{
    let TrainSetup {
        spec,
        splats,
        views,
        heldout,
    } = setup(events)?;
    let eval_every = spec.eval_every;
    let mut trainer = Trainer::new(spec, splats, views).map_err(|e| e.to_string())?;
    let total = trainer.total_steps();
    let _ = events.send(JobEvent::Log(format!(
        "training {} Gaussians on {} views for {total} steps",
        trainer.splats().len(),
        trainer.view_count()
    )));

    let mut paused_since = None;
    let mut train_time = Duration::ZERO;
    let mut last_snapshot: Option<Instant> = None;
    let mut cancelled = false;
    let mut rolled_back = 0;
    while !trainer.is_done() {
        if handle_control(control, &mut paused_since) {
            cancelled = true;
            break;
        }
        let started = Instant::now();
        let report = trainer.step();
        if let Some(reason) = report.rolled_back {
            rolled_back += 1;
            let _ = events.send(JobEvent::NanRolledBack {
                step: report.step,
                reason,
            });
        }
        let step = trainer.steps_done();
        let psnr =
            if !heldout.is_empty() && eval_every > 0 && step % eval_every == 0 && step < total {
                Some(trainer.evaluate(&heldout).psnr)
            } else {
                None
            };
        train_time += started.elapsed();
        let per_step = train_time.as_secs_f64() / step.max(1) as f64;
        let progress = Progress {
            step,
            total,
            loss: report.loss,
            psnr,
            gaussians: trainer.splats().len(),
            elapsed: train_time,
            eta: Duration::from_secs_f64(per_step * (total - step.min(total)) as f64),
        };
        if events.send(JobEvent::Progress(progress)).is_err() {
            // Nobody listens any more: stop working for nobody.
            cancelled = true;
            break;
        }
        if let Some(interval) = options.snapshot_interval
            && last_snapshot.is_none_or(|t| t.elapsed() >= interval)
        {
            last_snapshot = Some(Instant::now());
            let _ = events.send(JobEvent::Snapshot(Arc::new(trainer.splats().clone())));
        }
    }

    let started = Instant::now();
    let final_scores = (!heldout.is_empty()).then(|| trainer.evaluate(&heldout));
    train_time += started.elapsed();
    let steps = trainer.steps_done();
    let timings = trainer.timings().clone();
    let splats = Arc::new(trainer.into_splats());
    let _ = events.send(JobEvent::Snapshot(splats.clone()));
    Ok(TrainOutcome {
        splats,
        steps,
        total,
        cancelled,
        seconds: train_time.as_secs_f64(),
        heldout: final_scores,
        rolled_back,
        timings,
    })
}
