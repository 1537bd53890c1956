//! What several subcommands share: argument groups (a job's threads and progress bar, how a
//! dataset's photos are read, the held-out rule, how a training run starts, a project's scale),
//! the one conversion from arguments to a run, the value parsers, and drawing a job's progress
//! on the terminal.

use std::path::Path;
use std::time::Duration;

use anyhow::{Context, bail};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};

use damage_twin::damage::Palette;
use damage_twin::damage::setup::RunConfig;
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::timeline::lock::Writer;
use damage_twin::train::backend_choice::Backend;
use damage_twin::train::job::{Job, JobEvent, JobOptions, Progress};
use damage_twin::train::views::Holdout;

/// How a job runs on the terminal: the subcommands that start one long job share these.
#[derive(clap::Args, Debug)]
pub struct JobArgs {
    /// Worker threads (default: all cores, or RAYON_NUM_THREADS).
    #[arg(long, value_parser = parse_threads)]
    pub threads: Option<usize>,
    /// No progress bar (log lines only).
    #[arg(long)]
    pub quiet: bool,
}

impl JobArgs {
    /// A job run from the terminal on `--threads` workers.
    pub fn options(&self) -> JobOptions {
        JobOptions::headless(self.threads)
    }

    /// The number of threads the job runs on (for reports).
    pub fn thread_count(&self) -> usize {
        self.threads.unwrap_or_else(rayon::current_num_threads)
    }
}

/// How a dataset's photos are read: at which scale, composited on which background. Shared by
/// every subcommand that renders or trains against a dataset's views.
#[derive(clap::Args, Debug)]
pub struct ImageArgs {
    /// Image scale: 1, 2, 4, 8, 0.5, 0.25, 0.125 or w<width>.
    #[arg(long, default_value = "1", value_parser = parse_scale)]
    pub scale: ImageScale,
    /// Background: white, black or r,g,b in [0, 1].
    #[arg(long, default_value = "black", value_parser = parse_background)]
    pub background: Vec3,
}

/// How a training run reads its dataset and starts: shared by `train` and `bench`, so the two
/// time the same run.
#[derive(clap::Args, Debug)]
pub struct RunArgs {
    #[command(flatten)]
    pub images: ImageArgs,
    #[arg(long, default_value_t = 3)]
    pub sh_degree: u32,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub holdout: HoldoutArgs,
    /// Random initial points when the dataset has none (NeRF-synthetic, instant-ngp).
    #[arg(long, default_value_t = 100_000)]
    pub init_points: usize,
    /// The renderer that trains: cpu, gpu (any GPU through wgpu, a software driver included)
    /// or auto (a hardware GPU when there is one, else the CPU).
    #[arg(long, default_value = "cpu")]
    pub backend: Backend,
}

impl RunArgs {
    /// The run these arguments describe, `iterations` steps long; every other setting is
    /// `RunConfig::default()`'s, for the caller to override. The one place the CLI turns its
    /// arguments into a run.
    pub fn config(&self, iterations: u32) -> RunConfig {
        RunConfig {
            scale: self.images.scale,
            iterations,
            holdout: self.holdout.holdout(),
            sh_degree: self.sh_degree,
            seed: self.seed,
            background: self.images.background,
            random_points: self.init_points,
            backend: self.backend,
            ..RunConfig::default()
        }
    }
}

/// `--scale` where the twin project's scale is the default (`ProjectSettings::scale`).
#[derive(clap::Args, Debug)]
pub struct ProjectScaleArgs {
    /// Image scale: 1, 2, 4, 8, 0.5, 0.25, 0.125 or w<width> (default: the project's scale,
    /// `twin new --scale`).
    #[arg(long, value_parser = parse_scale)]
    pub scale: Option<ImageScale>,
}

impl ProjectScaleArgs {
    /// `--scale`, else the project's.
    pub fn or_project(&self, twin: &damage_twin::timeline::Twin) -> ImageScale {
        self.scale.unwrap_or(twin.project.settings.scale)
    }
}

/// How a command that writes a twin project waits for another writer (`timeline::lock`).
#[derive(clap::Args, Debug)]
pub struct LockArgs {
    /// Seconds to wait while another command writes the project before giving up (0: refuse at
    /// once).
    #[arg(long, default_value = "30", value_parser = parse_lock_wait)]
    pub lock_wait: Duration,
}

impl LockArgs {
    /// This process as the project's writer, named `command` to other writers; told on stderr
    /// when it has to wait.
    pub fn writer(&self, command: &str) -> Writer {
        Writer::new(command)
            .waiting(self.lock_wait)
            .telling(|message| eprintln!("{message}"))
    }
}

/// Up to a day: a longer wait is a writer stuck behind something else.
fn parse_lock_wait(text: &str) -> Result<Duration, String> {
    match text.trim().parse::<f64>() {
        Ok(s) if (0.0..=86_400.0).contains(&s) => Ok(Duration::from_secs_f64(s)),
        _ => Err(format!("{text:?}: expected seconds from 0 to 86400")),
    }
}

/// Which views are held out: the rule `train`, `bench`, `eval` and `study` share.
#[derive(clap::Args, Debug)]
pub struct HoldoutArgs {
    /// Hold out every n-th view (when the dataset has no test split).
    #[arg(long, default_value_t = 8)]
    pub test_every: usize,
    /// Hold out exactly these views (comma-separated names, e.g. 0049).
    #[arg(long, value_delimiter = ',')]
    pub test_views: Vec<String>,
}

impl HoldoutArgs {
    pub fn holdout(&self) -> Holdout {
        if self.test_views.is_empty() {
            Holdout::Auto {
                every: self.test_every,
            }
        } else {
            Holdout::Named(self.test_views.clone())
        }
    }
}

/// `--colour quakecity`: DESIGN.md's class colours, not colours chosen against the photos.
pub const FIXED_PALETTE: &str = "quakecity";

/// The palette with the user's `--colour class=r,g,b` overrides.
pub fn palette(overrides: &[String]) -> anyhow::Result<Palette> {
    let mut palette = Palette::default();
    for text in overrides.iter().filter(|t| *t != FIXED_PALETTE) {
        palette.set_from_text(text).map_err(anyhow::Error::msg)?;
    }
    Ok(palette)
}

/// Most worker threads a job may ask for: sixteen times the largest servers' core counts. Every
/// thread of a pool is spawned up front, so `--threads 100000` spent minutes spawning before
/// any work (and could exhaust the process's thread limit).
pub const MAX_THREADS: usize = 4096;

/// `--threads N`: 1 to `MAX_THREADS`.
pub fn parse_threads(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(n) if (1..=MAX_THREADS).contains(&n) => Ok(n),
        Ok(n) => Err(format!(
            "{n} threads: give 1 to {MAX_THREADS} (leave --threads out to use every core)"
        )),
        Err(_) => Err(format!("{text:?} is not a thread count")),
    }
}

pub fn parse_scale(text: &str) -> Result<ImageScale, String> {
    ImageScale::parse(text).ok_or_else(|| {
        format!(
            "bad scale {text:?}: use 1, 2, 4, 8, 0.5, 0.25, 0.125 or w<width> (a width from 1 to \
             {})",
            damage_twin::scene::limits::MAX_IMAGE_SIDE
        )
    })
}

/// `--survey NAME` of a survey being added: refused here, before any folder is made.
pub fn parse_survey_name(text: &str) -> Result<String, String> {
    damage_twin::scene::project::Survey::check_name(text).map_err(|e| e.to_string())?;
    Ok(text.to_string())
}

pub fn parse_background(text: &str) -> Result<Vec3, String> {
    match text {
        "white" => return Ok(Vec3::ONE),
        "black" => return Ok(Vec3::ZERO),
        _ => {}
    }
    let parts: Vec<f32> = text
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("bad background {text:?}: use white, black or r,g,b"))?;
    match parts[..] {
        [r, g, b] if [r, g, b].iter().all(|v| (0.0..=1.0).contains(v)) => Ok(Vec3::new(r, g, b)),
        _ => Err(format!(
            "bad background {text:?}: use white, black or r,g,b in [0, 1]"
        )),
    }
}

/// Opens a dataset with its images composited on `background`; prints its warnings.
pub fn open_dataset(path: &Path, background: Vec3) -> anyhow::Result<Dataset> {
    let options = OpenOptions {
        background: background.to_array(),
    };
    let dataset = Dataset::open(path, &options)
        .with_context(|| format!("opening dataset {}", path.display()))?;
    if dataset.views.is_empty() {
        bail!("{} has no usable views", path.display());
    }
    for warning in &dataset.warnings {
        eprintln!("warning: {warning}");
    }
    Ok(dataset)
}

/// Reads a model PLY.
pub fn read_model(path: &Path) -> anyhow::Result<damage_twin::splats::Splats> {
    damage_twin::splats::ply::read_splats(path)
        .with_context(|| format!("reading model {}", path.display()))
}

/// A line above a progress bar, or on stderr when the bar is hidden (stderr is not a terminal,
/// or `--quiet`: indicatif's `println` then prints nothing).
pub fn print_line(bar: &ProgressBar, line: String) {
    if bar.is_hidden() {
        eprintln!("{line}");
    } else {
        bar.println(line);
    }
}

/// Runs a job to its end on the terminal: a progress bar (hidden with `quiet`), log lines and
/// rolled-back steps above it, and every progress report handed to `on_progress` too (curves).
pub fn drive<R: Send + 'static>(
    job: Job<R>,
    what: &str,
    quiet: bool,
    mut on_progress: impl FnMut(&Progress),
) -> anyhow::Result<R> {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(0)
    };
    bar.set_style(
        ProgressStyle::with_template("{msg:>10} {bar:30} {pos}/{len} ETA {eta} | {prefix}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.enable_steady_tick(Duration::from_millis(250));
    let mut last_psnr: Option<f64> = None;
    let result = job.wait_with(|event| match event {
        JobEvent::Progress(p) => {
            on_progress(&p);
            if p.psnr.is_some() {
                last_psnr = p.psnr;
            }
            bar.set_message(p.phase);
            bar.set_length(u64::from(p.total));
            bar.set_position(u64::from(p.step));
            let loss = if p.loss.is_finite() {
                format!("loss {:.4} | ", p.loss)
            } else {
                String::new()
            };
            // A job with no model (segmentation) has no PSNR or Gaussians to show.
            if p.gaussians > 0 || last_psnr.is_some() || p.loss.is_finite() {
                bar.set_prefix(format!(
                    "{loss}held-out PSNR {} | {} Gaussians",
                    last_psnr
                        .map(|v| format!("{v:.2} dB"))
                        .unwrap_or_else(|| "-".into()),
                    p.gaussians
                ));
            }
        }
        JobEvent::Log(line) => print_line(&bar, line),
        JobEvent::NanRolledBack { step, reason } => {
            print_line(&bar, format!("step {step}: rolled back ({reason})"))
        }
        JobEvent::Snapshot(_) | JobEvent::Finished(_) | JobEvent::Failed(_) => {}
    });
    bar.finish_and_clear();
    result.with_context(|| format!("{what} failed"))
}
