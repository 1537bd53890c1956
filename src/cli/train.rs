//! `damage-twin train DATASET --out DIR`: opens a dataset, starts a training job and draws its
//! progress; writes `model.ply`, `metrics.json` and `curve.csv`. All training happens in the job.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, bail};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

use damage_twin::metrics::peak_rss_mb;
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::train::job::{JobEvent, JobOptions, TrainJob, TrainSetup};
use damage_twin::train::spec::{DensifyPolicy, TrainSpec};
use damage_twin::train::trainer::StageTimes;
use damage_twin::train::views::{Holdout, InitialModel, initial_splats, load_views, split_views};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Dataset folder (COLMAP, transforms.json or NeRF-synthetic).
    pub dataset: PathBuf,
    /// Output folder for model.ply, metrics.json and curve.csv.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, default_value_t = 7000)]
    pub iters: u32,
    /// Image scale: 1, 2, 4, 8, 0.25 or w<width>.
    #[arg(long, default_value = "1", value_parser = parse_scale)]
    pub scale: ImageScale,
    #[arg(long, default_value_t = 3)]
    pub sh_degree: u32,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Hold out every n-th view (when the dataset has no test split).
    #[arg(long, default_value_t = 8)]
    pub test_every: usize,
    /// Hold out exactly these views (comma-separated names, e.g. 0049).
    #[arg(long, value_delimiter = ',')]
    pub test_views: Vec<String>,
    /// Background: white, black or r,g,b in [0, 1].
    #[arg(long, default_value = "black", value_parser = parse_background)]
    pub background: Vec3,
    /// Training threads (default: all cores, or RAYON_NUM_THREADS).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Held-out PSNR is evaluated every this many steps for curve.csv (0: only at the end).
    #[arg(long, default_value_t = 500)]
    pub eval_every: u32,
    /// Cap on the Gaussian count (adaptive density control stops growing there).
    #[arg(long)]
    pub max_gaussians: Option<usize>,
    /// Random initial points when the dataset has none (NeRF-synthetic, instant-ngp).
    #[arg(long, default_value_t = 100_000)]
    pub init_points: usize,
    /// No progress bar (log lines only).
    #[arg(long)]
    pub quiet: bool,
}

pub fn parse_scale(text: &str) -> Result<ImageScale, String> {
    ImageScale::parse(text)
        .ok_or_else(|| format!("bad scale {text:?}: use 1, 2, 4, 8, 0.5, 0.25, 0.125 or w<width>"))
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

/// The held-out rule the `train`, `eval` and `render` commands share.
pub fn holdout(test_every: usize, test_views: &[String]) -> Holdout {
    if test_views.is_empty() {
        Holdout::Auto { every: test_every }
    } else {
        Holdout::Named(test_views.to_vec())
    }
}

/// Opens a dataset with its images composited on `background`.
pub fn open_dataset(path: &Path, background: Vec3) -> anyhow::Result<Dataset> {
    let options = OpenOptions {
        background: background.to_array(),
    };
    let dataset = Dataset::open(path, &options)
        .with_context(|| format!("opening dataset {}", path.display()))?;
    if dataset.views.is_empty() {
        bail!("{} has no usable views", path.display());
    }
    Ok(dataset)
}

#[derive(Serialize)]
struct Metrics {
    psnr: Option<f64>,
    ssim: Option<f64>,
    train_psnr: Option<f64>,
    gaussians: usize,
    iterations: u32,
    seconds: f64,
    ms_per_iteration: f64,
    peak_rss_mb: Option<f64>,
    heldout_views: Vec<String>,
    train_views: usize,
    width: u32,
    height: u32,
    threads: usize,
    rolled_back: u32,
    cancelled: bool,
    stage_ms_per_iteration: StageTimes,
}

/// A log line above the bar, or on stderr when the bar is hidden (`println` of a hidden bar
/// prints nothing).
fn log_line(bar: &ProgressBar, quiet: bool, line: String) {
    if quiet {
        eprintln!("{line}");
    } else {
        bar.println(line);
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let dataset = open_dataset(&args.dataset, args.background)?;
    for warning in &dataset.warnings {
        eprintln!("warning: {warning}");
    }
    let (train_idx, test_idx) = split_views(&dataset, &holdout(args.test_every, &args.test_views))
        .map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output folder {}", args.out.display()))?;

    let mut spec = TrainSpec::reconstruction(args.iters);
    spec.scale = args.scale;
    spec.sh_degree = args.sh_degree;
    spec.seed = args.seed;
    spec.background = args.background;
    spec.eval_every = args.eval_every;
    if let Some(max) = args.max_gaussians {
        spec.densify = DensifyPolicy::Budget { max };
    }
    let heldout_names: Vec<String> = test_idx
        .iter()
        .map(|&i| dataset.views[i].name.clone())
        .collect();
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);

    let init = InitialModel {
        sh_degree: args.sh_degree,
        label_channels: 0,
        random_points: args.init_points,
        seed: args.seed,
    };
    let load_dataset = dataset.clone();
    let (train_for_setup, test_for_setup) = (train_idx.clone(), test_idx.clone());
    let job = TrainJob::spawn_with(
        move |events| {
            let views = load_views(&load_dataset, &train_for_setup, spec.scale, false)
                .map_err(|e| e.to_string())?;
            let heldout = load_views(&load_dataset, &test_for_setup, spec.scale, false)
                .map_err(|e| e.to_string())?;
            let splats = initial_splats(&load_dataset, &views, &init)
                .map_err(|e| format!("initial Gaussians: {e}"))?;
            let _ = events.send(JobEvent::Log(format!(
                "loaded {} training and {} held-out views at {}x{}; {} initial Gaussians",
                views.len(),
                heldout.len(),
                views[0].image.width,
                views[0].image.height,
                splats.len()
            )));
            Ok(TrainSetup {
                spec,
                splats,
                views,
                heldout,
            })
        },
        JobOptions {
            threads: args.threads,
            snapshot_interval: None,
        },
    );

    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(args.iters as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} {per_sec} ETA {eta} | {msg}")
            .map_err(anyhow::Error::msg)?,
    );
    bar.enable_steady_tick(Duration::from_millis(250));
    let curve_path = args.out.join("curve.csv");
    let mut curve = std::io::BufWriter::new(
        std::fs::File::create(&curve_path)
            .with_context(|| format!("creating {}", curve_path.display()))?,
    );
    writeln!(curve, "step,seconds,loss,gaussians,heldout_psnr")?;
    let mut last_psnr: Option<f64> = None;
    let mut outcome = None;
    for event in job.events().iter() {
        match event {
            JobEvent::Progress(p) => {
                if p.psnr.is_some() {
                    last_psnr = p.psnr;
                }
                if p.psnr.is_some() || p.step % 10 == 0 || p.step == 1 {
                    let psnr = p.psnr.map(|v| format!("{v:.3}")).unwrap_or_default();
                    writeln!(
                        curve,
                        "{},{:.3},{:.6},{},{}",
                        p.step,
                        p.elapsed.as_secs_f64(),
                        p.loss,
                        p.gaussians,
                        psnr
                    )?;
                }
                bar.set_position(p.step as u64);
                bar.set_message(format!(
                    "loss {:.4} | held-out PSNR {} | {} Gaussians",
                    p.loss,
                    last_psnr
                        .map(|v| format!("{v:.2} dB"))
                        .unwrap_or_else(|| "-".into()),
                    p.gaussians
                ));
            }
            JobEvent::Log(line) => log_line(&bar, args.quiet, line),
            JobEvent::NanRolledBack { step, reason } => log_line(
                &bar,
                args.quiet,
                format!("step {step}: rolled back ({reason})"),
            ),
            JobEvent::Snapshot(_) => {}
            JobEvent::Finished(o) => outcome = Some(Ok(o)),
            JobEvent::Failed(e) => outcome = Some(Err(e)),
        }
    }
    bar.finish_and_clear();
    let outcome = match outcome {
        Some(Ok(o)) => o,
        Some(Err(e)) => bail!("training failed: {e}"),
        None => bail!("the training job ended without a result"),
    };

    // Final rows, then the model and the metrics.
    if let Some(scores) = &outcome.heldout {
        writeln!(
            curve,
            "{},{:.3},,{},{:.3}",
            outcome.steps,
            outcome.seconds,
            outcome.splats.len(),
            scores.psnr
        )?;
    }
    curve.flush()?;
    let model_path = args.out.join("model.ply");
    damage_twin::scene::ply::write_splats(&model_path, &outcome.splats)
        .with_context(|| format!("writing {}", model_path.display()))?;

    let peak_rss = peak_rss_mb();
    // Training-view PSNR on the final model (views reloaded: the job owned the first copies).
    let train_views = load_views(&dataset, &train_idx, args.scale, false)?;
    let train_psnr = damage_twin::train::trainer::evaluate_views(
        &outcome.splats,
        &train_views,
        args.background,
        args.sh_degree,
    )
    .map(|s| s.psnr);
    let (width, height) = train_views
        .first()
        .map(|v| (v.image.width, v.image.height))
        .unwrap_or((0, 0));
    let steps = outcome.steps.max(1) as f64;
    let metrics = Metrics {
        psnr: outcome.heldout.as_ref().map(|s| s.psnr),
        ssim: outcome.heldout.as_ref().map(|s| s.ssim),
        train_psnr,
        gaussians: outcome.splats.len(),
        iterations: outcome.steps,
        seconds: outcome.seconds,
        ms_per_iteration: outcome.seconds * 1000.0 / steps,
        peak_rss_mb: peak_rss,
        heldout_views: heldout_names,
        train_views: train_idx.len(),
        width,
        height,
        threads,
        rolled_back: outcome.rolled_back,
        cancelled: outcome.cancelled,
        stage_ms_per_iteration: outcome.timings.per_step_ms(outcome.steps),
    };
    let metrics_path = args.out.join("metrics.json");
    std::fs::write(&metrics_path, serde_json::to_string_pretty(&metrics)?)
        .with_context(|| format!("writing {}", metrics_path.display()))?;
    println!("{}", serde_json::to_string_pretty(&metrics)?);
    Ok(())
}
