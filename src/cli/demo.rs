//! `damage-twin demo`: the built-in demo building. With `--headless`, the same run as the viewer
//! without a window: synth → train → held-out evaluation → renders, metrics and charts in `--out`.
//! Without it, opens the viewer on the demo. A client of `synth`, `train::job` and `app`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};

use damage_twin::app::history::{EvalSample, History, Sample};
use damage_twin::app::settings::{Settings, TrainMode, TrainingSettings};
use damage_twin::app::{chart_export, demo, files, snapshot, train_setup};
use damage_twin::damage::evaluate::DamageReadout;
use damage_twin::damage::setup::effective_mode;
use damage_twin::scene::Dataset;
use damage_twin::scene::open::OpenOptions;
use damage_twin::train::job::{JobEvent, JobOptions, TrainJob};

use super::train::print_line;

#[derive(clap::Args)]
pub struct Args {
    /// Run without a window and write the results to `--out`.
    #[arg(long)]
    headless: bool,
    /// Output folder of the headless run.
    #[arg(long, default_value = "demo-out")]
    out: PathBuf,
    /// Training iterations (the default finishes within 5 minutes on 2 cores).
    #[arg(long, default_value_t = 1500)]
    iterations: u32,
    /// Number of survey views to generate (0: synth's default).
    #[arg(long, default_value_t = 0)]
    views: usize,
    /// Image size the demo is generated at.
    #[arg(long, default_value_t = 480)]
    width: u32,
    #[arg(long, default_value_t = 270)]
    height: u32,
    /// Training mode: rgb, overlay or label.
    #[arg(long, default_value = "label")]
    mode: TrainMode,
    /// Held-out views rendered into `renders/`.
    #[arg(long, default_value_t = 3)]
    renders: usize,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.headless {
        return damage_twin::app::run(damage_twin::app::Launch::Demo);
    }
    let started = Instant::now();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let data_dir = args.out.join("dataset");

    // 1. The demo building.
    let bar = ProgressBar::new(1000).with_style(
        ProgressStyle::with_template("{msg:>12} [{bar:40}] {percent:>3}% {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message("synth");
    let data_dir = demo::ensure(&data_dir, args.views, args.width, args.height, &|f, _| {
        bar.set_position((f * 1000.0) as u64)
    })?;
    bar.finish();
    let synth_s = started.elapsed().as_secs_f64();
    let dataset = Arc::new(
        Dataset::open(&data_dir, &OpenOptions::default())
            .with_context(|| format!("opening {}", data_dir.display()))?,
    );
    eprintln!(
        "demo building: {} views in {} ({synth_s:.1} s)",
        dataset.views.len(),
        data_dir.display()
    );

    // 2. Training, exactly as the viewer starts it.
    // Trained at 240×135 like the viewer's demo (a quarter of its 960×540; half of this 480×270).
    let training = TrainingSettings {
        iterations: args.iterations,
        resolution_factor: 2,
        mode: args.mode,
        ..TrainingSettings::default()
    };
    let settings = Settings {
        training: training.clone(),
        ..Settings::default()
    };
    let for_worker = dataset.clone();
    let palette = damage_twin::damage::Palette {
        colours: settings.damage.colours,
    };
    let config = train_setup::run_config(&training, palette, [0.0; 3]);
    let (_, heldout_indices) = damage_twin::train::views::split_views(&dataset, &config.holdout)
        .map_err(anyhow::Error::msg)?;
    let (eval_scale, eval_mode) = (config.scale, effective_mode(&dataset, config.mode));
    let job = TrainJob::spawn_with(
        move |log| train_setup::setup(&for_worker, &config, Some(log)),
        JobOptions {
            threads: None,
            snapshot_interval: None,
            low_priority: false,
        },
    );
    let bar = ProgressBar::new(u64::from(args.iterations)).with_style(
        ProgressStyle::with_template("{msg:>12} [{bar:40}] {pos}/{len} {elapsed} ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message("train");
    let train_started = Instant::now();
    let mut history = History::default();
    let mut outcome = None;
    for event in job.events().iter() {
        match event {
            JobEvent::Progress(p) => {
                let wall_s = train_started.elapsed().as_secs_f64();
                history.push(Sample {
                    wall_s,
                    step: p.step,
                    loss: f64::from(p.loss),
                    psnr: f64::NAN,
                    gaussians: p.gaussians,
                });
                if let Some(psnr) = p.psnr {
                    history.push_eval(EvalSample {
                        wall_s,
                        step: p.step,
                        psnr,
                    });
                    print_line(&bar, format!("step {}: held-out PSNR {psnr:.2} dB", p.step));
                }
                bar.set_position(u64::from(p.step));
            }
            JobEvent::Log(line) => print_line(&bar, line),
            JobEvent::NanRolledBack { step, reason } => {
                print_line(&bar, format!("step {step} rolled back: {reason}"))
            }
            JobEvent::Snapshot(_) => {}
            JobEvent::Finished(o) => outcome = Some(Ok(o)),
            JobEvent::Failed(e) => outcome = Some(Err(e)),
        }
    }
    bar.finish();
    let outcome = outcome
        .unwrap_or_else(|| Err("the training job ended without a result".into()))
        .map_err(|e| anyhow::anyhow!("training failed: {e}"))?;
    if let (Some(scores), Some(last)) = (&outcome.heldout, history.last()) {
        history.push_eval(EvalSample {
            wall_s: last.wall_s,
            step: last.step,
            psnr: scores.psnr,
        });
    }

    // 3. Model, renders, metrics, charts.
    files::export_ply(&args.out.join("model.ply"), &outcome.splats)?;
    let renders = write_renders(
        &args.out,
        &dataset,
        &outcome.splats,
        &settings,
        args.renders,
    )?;
    let charts = chart_export::write_training_charts(&args.out, &history)?;
    let readout = DamageReadout {
        mode: eval_mode,
        ..DamageReadout::for_model(&outcome.splats, palette)
    };
    let damage = crate::cli::train::damage_figures(
        &dataset,
        &heldout_indices,
        eval_scale,
        &outcome.splats,
        &readout,
        glam::Vec3::ZERO,
    )?
    .map(|(_, figures)| figures);
    if let Some(d) = &damage {
        eprintln!("held-out damage IoU: {:?}", d.iou);
    }
    let metrics = serde_json::json!({
        "dataset": data_dir,
        "views": dataset.views.len(),
        "mode": args.mode,
        "iterations": outcome.steps,
        "gaussians": outcome.splats.len(),
        "train_seconds": outcome.seconds,
        "synth_seconds": synth_s,
        "total_seconds": started.elapsed().as_secs_f64(),
        "heldout_psnr": outcome.heldout.as_ref().map(|s| s.psnr),
        "heldout_ssim": outcome.heldout.as_ref().map(|s| s.ssim),
        "damage": damage,
        "rolled_back_steps": outcome.rolled_back,
        "peak_rss_mb": damage_twin::metrics::peak_rss_mb(),
        "renders": renders,
        "charts": charts,
        "history": history,
    });
    let metrics_path = args.out.join("metrics.json");
    files::write_atomically(&metrics_path, |tmp| {
        std::fs::write(tmp, serde_json::to_string_pretty(&metrics)?)
            .with_context(|| format!("writing {}", metrics_path.display()))
    })?;
    eprintln!(
        "done in {:.1} s: {} Gaussians, held-out PSNR {} → {}",
        started.elapsed().as_secs_f64(),
        outcome.splats.len(),
        outcome
            .heldout
            .as_ref()
            .map(|s| format!("{:.2} dB", s.psnr))
            .unwrap_or_else(|| "–".into()),
        args.out.display()
    );
    Ok(())
}

/// Renders up to `count` held-out views (every 8th) beside their photos into `renders/`.
fn write_renders(
    out: &Path,
    dataset: &Dataset,
    splats: &damage_twin::splats::Splats,
    settings: &Settings,
    count: usize,
) -> anyhow::Result<Vec<PathBuf>> {
    let dir = out.join("renders");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut written = Vec::new();
    for index in (0..dataset.views.len()).step_by(8).take(count) {
        let view = &dataset.views[index];
        let path = dir.join(format!("{}.png", view.name.replace('/', "_")));
        snapshot::render_png(&path, splats, &view.camera, settings)?;
        written.push(path);
    }
    Ok(written)
}
