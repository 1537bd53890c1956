//! `damage-twin train DATASET --out DIR`: opens a dataset, starts a training job and draws its
//! progress; writes `model.ply`, `metrics.json` and `curve.csv`. All training happens in the job.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, bail};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

use damage_twin::damage::evaluate::{DamageFigures, DamageReadout, evaluate_damage};
use damage_twin::damage::reference::{load_reference_views, reference_source};
use damage_twin::damage::setup::{RunConfig, effective_mode, prepare_run};
use damage_twin::damage::{Palette, TrainMode};
use damage_twin::metrics::peak_rss_mb;
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::train::job::{JobEvent, JobOptions, TrainJob};
use damage_twin::train::trainer::StageTimes;
use damage_twin::train::views::{Holdout, load_views, split_views};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Dataset folder (COLMAP, transforms.json or NeRF-synthetic).
    pub dataset: PathBuf,
    /// Output folder for model.ply, metrics.json and curve.csv.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, default_value_t = 7000)]
    pub iters: u32,
    #[command(flatten)]
    pub run: RunArgs,
    /// Held-out PSNR is evaluated every this many steps for curve.csv (0: only at the end).
    #[arg(long, default_value_t = 500)]
    pub eval_every: u32,
    /// Cap on the Gaussian count (adaptive density control stops growing there).
    #[arg(long)]
    pub max_gaussians: Option<usize>,
    /// No progress bar (log lines only).
    #[arg(long)]
    pub quiet: bool,
    /// Damage supervision: rgb, overlay (masks painted into the photos) or label (per-Gaussian
    /// damage channels). Damage modes fall back to rgb on a dataset without masks.
    #[arg(long, default_value = "label")]
    pub mode: TrainMode,
    /// Weight of the label loss beside the photometric loss (label mode).
    #[arg(long, default_value_t = RunConfig::default().label_weight)]
    pub label_weight: f32,
    /// Class colour override for overlay mode, class=r,g,b (repeatable), e.g. crack=0,0,255.
    #[arg(long = "colour")]
    pub colours: Vec<String>,
    /// Weight of damage pixels in the label cross-entropy (label mode).
    #[arg(long, default_value_t = RunConfig::default().label_pos_weight)]
    pub label_pos_weight: f32,
    /// Learning rate of the label logits (label mode).
    #[arg(long, default_value_t = RunConfig::default().label_lr.unwrap_or(0.05))]
    pub label_lr: f32,
}

/// How a run reads its dataset and starts: shared by `train` and `bench`, so the two time the
/// same run.
#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// Image scale: 1, 2, 4, 8, 0.25 or w<width>.
    #[arg(long, default_value = "1", value_parser = parse_scale)]
    pub scale: ImageScale,
    #[arg(long, default_value_t = 3)]
    pub sh_degree: u32,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub holdout: HoldoutArgs,
    /// Background: white, black or r,g,b in [0, 1].
    #[arg(long, default_value = "black", value_parser = parse_background)]
    pub background: Vec3,
    /// Training threads (default: all cores, or RAYON_NUM_THREADS).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Random initial points when the dataset has none (NeRF-synthetic, instant-ngp).
    #[arg(long, default_value_t = 100_000)]
    pub init_points: usize,
}

/// The palette with the user's `--colour` overrides.
pub fn palette(overrides: &[String]) -> anyhow::Result<Palette> {
    let mut palette = Palette::default();
    for text in overrides {
        palette.set_from_text(text).map_err(anyhow::Error::msg)?;
    }
    Ok(palette)
}

/// Damage figures of `splats` on the views `indices` against the reference masks (`truth/` when
/// present); None when the dataset has no masks or nothing is evaluated.
pub fn damage_figures(
    dataset: &Dataset,
    indices: &[usize],
    scale: ImageScale,
    splats: &damage_twin::splats::Splats,
    readout: &DamageReadout,
    background: Vec3,
) -> anyhow::Result<Option<(String, DamageFigures)>> {
    let Some(source) = reference_source(dataset) else {
        return Ok(None);
    };
    if indices.is_empty() || readout.mode == TrainMode::Rgb {
        return Ok(None);
    }
    let views = load_reference_views(dataset, &source, indices, scale)?;
    let scores = evaluate_damage(splats, &views, readout, background);
    Ok(Some((source.dir().display().to_string(), scores.figures())))
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
    /// The SIMD build the CPU kernels ran (`DAMAGE_TWIN_SIMD` can lower it).
    simd: &'static str,
    rolled_back: u32,
    cancelled: bool,
    stage_ms_per_iteration: StageTimes,
    mode: TrainMode,
    /// Rendered damage against the reference masks on the held-out views.
    damage: Option<DamageFigures>,
    /// The same on the training views.
    damage_train: Option<DamageFigures>,
    damage_reference: Option<String>,
}

/// A log line above the bar, or on stderr when the bar is hidden (`println` of a hidden bar
/// prints nothing).
fn log_line(bar: &ProgressBar, quiet: bool, line: String) {
    if quiet {
        eprintln!("{line}");
    } else {
        print_line(bar, line);
    }
}

/// A line above a progress bar, or on stderr when the bar is hidden (stderr is not a terminal:
/// indicatif's `println` then prints nothing).
pub fn print_line(bar: &ProgressBar, line: String) {
    if bar.is_hidden() {
        eprintln!("{line}");
    } else {
        bar.println(line);
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let dataset = open_dataset(&args.dataset, args.run.background)?;
    for warning in &dataset.warnings {
        eprintln!("warning: {warning}");
    }
    let (train_idx, test_idx) =
        split_views(&dataset, &args.run.holdout.holdout()).map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output folder {}", args.out.display()))?;

    let config = RunConfig {
        mode: args.mode,
        palette: palette(&args.colours)?,
        scale: args.run.scale,
        iterations: args.iters,
        holdout: args.run.holdout.holdout(),
        sh_degree: args.run.sh_degree,
        seed: args.run.seed,
        background: args.run.background,
        label_weight: args.label_weight,
        label_pos_weight: args.label_pos_weight,
        label_lr: Some(args.label_lr),
        random_points: args.run.init_points,
        eval_every: args.eval_every,
        max_gaussians: args.max_gaussians,
    };
    let mode = effective_mode(&dataset, args.mode);
    let heldout_names: Vec<String> = test_idx
        .iter()
        .map(|&i| dataset.views[i].name.clone())
        .collect();
    let threads = args.run.threads.unwrap_or_else(rayon::current_num_threads);

    let load_dataset = dataset.clone();
    let job = TrainJob::spawn_with(
        move |events| {
            let run = prepare_run(&load_dataset, &config)?;
            for note in run.notes {
                let _ = events.send(JobEvent::Log(note));
            }
            Ok(run.setup)
        },
        JobOptions {
            threads: args.run.threads,
            snapshot_interval: None,
            low_priority: false,
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
    let train_views = load_views(&dataset, &train_idx, args.run.scale, false)?;
    let train_psnr = damage_twin::train::evaluate::evaluate_views(
        &outcome.splats,
        &train_views,
        args.run.background,
        args.run.sh_degree,
    )
    .map(|s| s.psnr);
    let readout = DamageReadout {
        mode,
        ..DamageReadout::for_model(&outcome.splats, palette(&args.colours)?)
    };
    let damage = damage_figures(
        &dataset,
        &test_idx,
        args.run.scale,
        &outcome.splats,
        &readout,
        args.run.background,
    )?;
    let damage_train = damage_figures(
        &dataset,
        &train_idx,
        args.run.scale,
        &outcome.splats,
        &readout,
        args.run.background,
    )?;
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
        simd: damage_twin::simd::simd_level().name(),
        rolled_back: outcome.rolled_back,
        cancelled: outcome.cancelled,
        stage_ms_per_iteration: outcome.timings.per_step_ms(outcome.steps),
        mode,
        damage_reference: damage
            .as_ref()
            .or(damage_train.as_ref())
            .map(|d| d.0.clone()),
        damage: damage.map(|d| d.1),
        damage_train: damage_train.map(|d| d.1),
    };
    let metrics_path = args.out.join("metrics.json");
    std::fs::write(&metrics_path, serde_json::to_string_pretty(&metrics)?)
        .with_context(|| format!("writing {}", metrics_path.display()))?;
    println!("{}", serde_json::to_string_pretty(&metrics)?);
    Ok(())
}
