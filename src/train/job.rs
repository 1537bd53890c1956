//! The job API (DESIGN.md): one step of the pipeline (train, evaluate, render, bench; refine,
//! detect and update next) on a worker thread that reports progress, `Arc` snapshots, log lines
//! and one final result or typed error over a crossbeam channel, and obeys pause / resume /
//! cancel sent the other way. The app and the CLI are clients of this; no algorithm lives here.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender, TryRecvError};

use crate::scene::SceneError;
use crate::splats::Splats;
use crate::splats::init::InitError;
use crate::train::priority;
use crate::train::trainer::TrainError;

/// One progress report.
#[derive(Clone, Debug)]
pub struct Progress {
    /// What the job is doing (`"train"`, `"evaluate"`, `"select"`, …).
    pub phase: &'static str,
    /// Steps of this phase done so far (1-based after the first step).
    pub step: u32,
    pub total: u32,
    /// Loss of the last training step (NaN when the step was rolled back or the phase does not
    /// train).
    pub loss: f32,
    /// Held-out PSNR, present on the steps where the held-out views were evaluated.
    pub psnr: Option<f64>,
    pub gaussians: usize,
    /// Working time of the phase, pauses excluded.
    pub elapsed: Duration,
    /// Remaining time at the current rate.
    pub eta: Duration,
}

impl Progress {
    /// Step `step` of `total` of a phase that neither trains nor times itself (selecting,
    /// drawing hulls), over `gaussians` Gaussians.
    pub fn counted(phase: &'static str, step: usize, total: usize, gaussians: usize) -> Progress {
        Progress {
            phase,
            step: step as u32,
            total: total as u32,
            loss: f32::NAN,
            psnr: None,
            gaussians,
            elapsed: Duration::ZERO,
            eta: Duration::ZERO,
        }
    }
}

/// Why a job failed.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Train(#[from] TrainError),
    #[error("initial Gaussians: {0}")]
    Init(#[from] InitError),
    /// A request that cannot run as asked (no held-out views to evaluate, …).
    #[error("{0}")]
    Invalid(String),
    /// An error of a layer above `train` (damage, timeline, report).
    #[error(transparent)]
    Other(Box<dyn std::error::Error + Send + Sync>),
    #[error("cannot start the job: {0}")]
    Start(String),
    #[error("the job's worker stopped without a result (it panicked)")]
    NoResult,
}

impl JobError {
    pub fn other(error: impl std::error::Error + Send + Sync + 'static) -> JobError {
        JobError::Other(Box::new(error))
    }
}

/// Events from the worker, in order; `Finished` or `Failed` is always the last one.
#[derive(Debug)]
pub enum JobEvent<R> {
    Progress(Progress),
    /// The current model, at most every `JobOptions::snapshot_interval` and once at the end.
    Snapshot(Arc<Splats>),
    Log(String),
    /// A training step produced NaN or Inf and was undone; training continues.
    NanRolledBack {
        step: u32,
        reason: String,
    },
    Finished(R),
    Failed(JobError),
}

/// Control messages from the client.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    Pause,
    Resume,
    Cancel,
}

/// How a job runs (not what it does).
#[derive(Clone, Copy, Debug)]
pub struct JobOptions {
    /// Rayon threads for this job; `None` uses the default (RAYON_NUM_THREADS or every core).
    pub threads: Option<usize>,
    /// Minimum time between snapshots (DESIGN.md: at most ~10 per second); `None` sends only the
    /// final one (the CLI, which draws no splats).
    pub snapshot_interval: Option<Duration>,
    /// Run the worker and its rayon threads at a lower scheduling priority
    /// (`train::priority`): the viewer's frames come first, the job takes the rest.
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

impl JobOptions {
    /// What the CLI runs with: default threads, no intermediate snapshots.
    pub fn headless(threads: Option<usize>) -> JobOptions {
        JobOptions {
            threads,
            snapshot_interval: None,
            low_priority: false,
        }
    }
}

/// What a job's work sees: the way to report and to hear pause and cancel. Not generic over the
/// result, so one training loop serves every job that trains (train, refine, update).
pub struct JobContext<'a> {
    send: Box<dyn Fn(Update) -> bool + 'a>,
    control: &'a Receiver<Control>,
    snapshot_interval: Option<Duration>,
    last_snapshot: Option<Instant>,
    paused_since: Option<Instant>,
    cancelled: bool,
    /// Set by `Job::cancel` (and a dropped handle) at once, for work blocked where it cannot
    /// call `should_stop`: an external program it waits on (COLMAP) polls it instead.
    cancel_flag: Arc<AtomicBool>,
    /// The progress kept as a training history since `keep_history` (a job that writes its own
    /// record, as an update's commit does, keeps it with the model).
    history: std::cell::RefCell<Option<(Instant, crate::train::history::History)>>,
}

/// The events a job's work sends (the final one is its return value).
enum Update {
    Progress(Progress),
    Snapshot(Arc<Splats>),
    Log(String),
    NanRolledBack { step: u32, reason: String },
}

impl<R> From<Update> for JobEvent<R> {
    fn from(update: Update) -> Self {
        match update {
            Update::Progress(p) => JobEvent::Progress(p),
            Update::Snapshot(s) => JobEvent::Snapshot(s),
            Update::Log(l) => JobEvent::Log(l),
            Update::NanRolledBack { step, reason } => JobEvent::NanRolledBack { step, reason },
        }
    }
}

impl<'a> JobContext<'a> {
    fn new<R: 'a>(
        events: &'a Sender<JobEvent<R>>,
        control: &'a Receiver<Control>,
        cancel_flag: Arc<AtomicBool>,
        options: &JobOptions,
    ) -> JobContext<'a> {
        JobContext {
            send: Box::new(move |update| events.send(update.into()).is_ok()),
            control,
            snapshot_interval: options.snapshot_interval,
            last_snapshot: None,
            paused_since: None,
            cancelled: false,
            cancel_flag,
            history: std::cell::RefCell::new(None),
        }
    }

    /// A log line for the user.
    pub fn log(&self, line: impl Into<String>) {
        (self.send)(Update::Log(line.into()));
    }

    /// Reports progress; false when nobody listens any more (the work should stop).
    pub fn progress(&self, progress: Progress) -> bool {
        if let Some((started, history)) = self.history.borrow_mut().as_mut() {
            history.record_progress(&progress, started.elapsed().as_secs_f64());
        }
        (self.send)(Update::Progress(progress))
    }

    /// From now on, progress is also kept as a training history (wall time from now).
    pub fn keep_history(&mut self) {
        *self.history.get_mut() = Some((Instant::now(), Default::default()));
    }

    /// The history kept since `keep_history` (empty without), and its wall time so far.
    pub fn take_history(&mut self) -> (crate::train::history::History, f64) {
        match self.history.get_mut().take() {
            Some((started, history)) => (history, started.elapsed().as_secs_f64()),
            None => Default::default(),
        }
    }

    /// Reports a rolled-back training step.
    pub fn rolled_back(&self, step: u32, reason: String) {
        (self.send)(Update::NanRolledBack { step, reason });
    }

    /// Sends a snapshot made by `make` when the snapshot interval has passed (never in a job
    /// without one).
    pub fn snapshot_every(&mut self, make: impl FnOnce() -> Splats) {
        if let Some(interval) = self.snapshot_interval
            && self.last_snapshot.is_none_or(|t| t.elapsed() >= interval)
        {
            self.last_snapshot = Some(Instant::now());
            (self.send)(Update::Snapshot(Arc::new(make())));
        }
    }

    /// Sends a snapshot now (the final model).
    pub fn snapshot(&self, splats: Arc<Splats>) {
        (self.send)(Update::Snapshot(splats));
    }

    /// A flag that turns true as soon as the job is cancelled, readable from any thread (pause
    /// does not reach it): for work that waits on something other than this context.
    pub fn cancel_flag(&self) -> Arc<AtomicBool> {
        self.cancel_flag.clone()
    }

    /// Applies pending control messages, blocking while paused. True once the job was cancelled
    /// (or its client is gone while paused): the work should stop at the next safe point.
    pub fn should_stop(&mut self) -> bool {
        while !self.cancelled {
            let message = if self.paused_since.is_some() {
                match self.control.recv() {
                    Ok(m) => m,
                    // Client gone while paused: nobody can resume, so stop.
                    Err(_) => Control::Cancel,
                }
            } else {
                match self.control.try_recv() {
                    Ok(m) => m,
                    Err(TryRecvError::Empty) | Err(TryRecvError::Disconnected) => return false,
                }
            };
            match message {
                Control::Cancel => self.cancelled = true,
                Control::Pause => {
                    self.paused_since.get_or_insert_with(Instant::now);
                }
                Control::Resume => self.paused_since = None,
            }
        }
        true
    }
}

/// A running job. Dropping the handle cancels the job and waits for the worker.
pub struct Job<R> {
    events: Receiver<JobEvent<R>>,
    control: Sender<Control>,
    /// `JobContext::cancel_flag`.
    cancelled: Arc<AtomicBool>,
    worker: Option<JoinHandle<()>>,
}

impl<R: Send + 'static> Job<R> {
    /// Starts `work` on a worker thread named `damage-twin-<name>`, inside a rayon pool of its
    /// own. Its `Ok` ends the job with `Finished`, its `Err` with `Failed`.
    pub fn spawn<F>(name: &str, options: JobOptions, work: F) -> Job<R>
    where
        F: FnOnce(&mut JobContext) -> Result<R, JobError> + Send + 'static,
    {
        let (event_tx, events) = crossbeam_channel::unbounded();
        let (control, control_rx) = crossbeam_channel::unbounded();
        let cancelled = Arc::new(AtomicBool::new(false));
        let cancel_flag = cancelled.clone();
        let worker = std::thread::Builder::new()
            .name(format!("damage-twin-{name}"))
            .spawn(move || {
                if options.low_priority {
                    priority::lower_current_thread_priority();
                }
                let body = || {
                    let mut context =
                        JobContext::new(&event_tx, &control_rx, cancel_flag, &options);
                    work(&mut context)
                };
                // Always inside a pool of our own, even at the default size: started from this
                // plain thread, every parallel loop of a training step (~25) would hand its work
                // to the global pool and sleep until it came back, two wake-ups per loop (3-7 %
                // of user CPU per step at one thread on fox_bench_ds8, and 6x the system time).
                // A low-priority job's pool threads are lowered as they start.
                let threads = options.threads.unwrap_or(0);
                let mut pool = rayon::ThreadPoolBuilder::new().num_threads(threads);
                if options.low_priority {
                    pool = pool.start_handler(|_| priority::lower_current_thread_priority());
                }
                let result = match pool.build() {
                    Ok(pool) => pool.install(body),
                    Err(e) => Err(JobError::Start(format!("the worker threads: {e}"))),
                };
                let last = match result {
                    Ok(outcome) => JobEvent::Finished(outcome),
                    Err(e) => JobEvent::Failed(e),
                };
                // The receiver may be gone (client dropped); nothing to report to then.
                let _ = event_tx.send(last);
            });
        match worker {
            Ok(handle) => Job {
                events,
                control,
                cancelled,
                worker: Some(handle),
            },
            Err(e) => {
                // No thread: report the failure through the channel like any other.
                let (tx, rx) = crossbeam_channel::unbounded();
                let _ = tx.send(JobEvent::Failed(JobError::Start(format!(
                    "the worker thread: {e}"
                ))));
                Job {
                    events: rx,
                    control,
                    cancelled,
                    worker: None,
                }
            }
        }
    }

    /// The event stream; ends after `Finished` or `Failed`.
    pub fn events(&self) -> &Receiver<JobEvent<R>> {
        &self.events
    }

    pub fn pause(&self) {
        let _ = self.control.send(Control::Pause);
    }

    pub fn resume(&self) {
        let _ = self.control.send(Control::Resume);
    }

    pub fn cancel(&self) {
        self.cancelled.store(true, Ordering::Relaxed);
        let _ = self.control.send(Control::Cancel);
    }

    /// True once the worker thread has ended.
    pub fn is_finished(&self) -> bool {
        self.worker.as_ref().is_none_or(|w| w.is_finished())
    }

    /// Blocks until the job ends and returns its result, draining the other events.
    pub fn wait(self) -> Result<R, JobError> {
        self.wait_with(|_| {})
    }

    /// Blocks until the job ends, handing every event but the last to `on_event` (a progress
    /// bar, a log), and returns the result.
    pub fn wait_with(mut self, mut on_event: impl FnMut(JobEvent<R>)) -> Result<R, JobError> {
        let mut last = Err(JobError::NoResult);
        for event in self.events.iter() {
            match event {
                JobEvent::Finished(outcome) => last = Ok(outcome),
                JobEvent::Failed(e) => last = Err(e),
                other => on_event(other),
            }
        }
        if let Some(worker) = self.worker.take()
            && worker.join().is_err()
        {
            return Err(JobError::NoResult);
        }
        last
    }
}

impl<R> Drop for Job<R> {
    fn drop(&mut self) {
        if let Some(worker) = self.worker.take() {
            self.cancelled.store(true, Ordering::Relaxed);
            let _ = self.control.send(Control::Cancel);
            let _ = worker.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_job_reports_its_logs_then_its_result() {
        let job = Job::spawn("test", JobOptions::headless(Some(1)), |ctx| {
            ctx.log("working");
            Ok(41 + 1)
        });
        let mut logs = Vec::new();
        let result = job.wait_with(|event| {
            if let JobEvent::Log(line) = event {
                logs.push(line);
            }
        });
        assert_eq!(result.unwrap(), 42);
        assert_eq!(logs, vec!["working".to_string()]);
    }

    #[test]
    fn a_failing_job_ends_with_its_typed_error() {
        let job: Job<()> = Job::spawn("test", JobOptions::headless(Some(1)), |_| {
            Err(JobError::Invalid("nothing to do".into()))
        });
        assert!(matches!(job.wait(), Err(JobError::Invalid(m)) if m == "nothing to do"));
    }

    #[test]
    fn cancel_reaches_the_work_while_paused() {
        let (started_tx, started) = crossbeam_channel::bounded(1);
        let job = Job::spawn("test", JobOptions::headless(Some(1)), move |ctx| {
            let _ = started_tx.send(());
            let mut checks = 0u64;
            while !ctx.should_stop() {
                checks += 1;
                std::thread::sleep(Duration::from_millis(1));
            }
            Ok(checks)
        });
        started.recv().unwrap();
        job.pause();
        job.cancel();
        assert!(
            job.wait().is_ok(),
            "a cancelled job still returns what it did"
        );
    }

    #[test]
    fn cancel_sets_the_flag_that_blocked_work_polls() {
        let (started_tx, started) = crossbeam_channel::bounded(1);
        let job = Job::spawn("test", JobOptions::headless(Some(1)), move |ctx| {
            let flag = ctx.cancel_flag();
            let _ = started_tx.send(());
            // Work that never calls `should_stop` (waiting on a program) sees the flag alone.
            let start = Instant::now();
            while !flag.load(Ordering::Relaxed) {
                if start.elapsed() > Duration::from_secs(10) {
                    return Err(JobError::Invalid("the cancel never arrived".into()));
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            Ok(())
        });
        started.recv().unwrap();
        job.cancel();
        job.wait().unwrap();
    }

    #[test]
    fn a_panicking_job_reports_no_result() {
        let job: Job<()> = Job::spawn("test", JobOptions::headless(Some(1)), |_| {
            panic!("deliberate test panic")
        });
        assert!(matches!(job.wait(), Err(JobError::NoResult)));
    }
}
