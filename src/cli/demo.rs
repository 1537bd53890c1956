//! `damage-twin demo`: the built-in demo building. With `--headless`, the viewer's run without a
//! window: synth → train → held-out evaluation → renders, metrics and charts in `--out`.
//! Without it, opens the viewer on the demo. A client of `synth`, `damage` and `report`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};

use damage_twin::damage::assess::{EvalRequest, evaluate_model};
use damage_twin::damage::display::{DisplayStyle, render_png};
use damage_twin::damage::evaluate::DamageReadout;
use damage_twin::damage::setup::{RunConfig, TrainingSettings, effective_mode, train_job};
use damage_twin::damage::{Palette, TrainMode};
use damage_twin::report::training_chart::write_training_charts;
use damage_twin::scene::Dataset;
use damage_twin::scene::atomic::write_atomic;
use damage_twin::scene::open::OpenOptions;
use damage_twin::train::history::History;
use damage_twin::train::job::JobOptions;
use damage_twin::train::views::split_views;

use super::args::drive;

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
        return super::launch::demo_window();
    }
    let started = Instant::now();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;

    // 1. The demo building.
    let bar = ProgressBar::new(1000).with_style(
        ProgressStyle::with_template("{msg:>12} [{bar:40}] {percent:>3}% {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message("synth");
    let data_dir = damage_twin::synth::demo::ensure(
        &args.out.join("dataset"),
        args.views,
        args.width,
        args.height,
        &|f, _| bar.set_position((f * 1000.0) as u64),
    )?;
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

    // 2. Training, exactly as the viewer starts it, at half of this 480×270 (240×135, the
    // viewer demo's quarter of 960×540).
    let training = TrainingSettings {
        iterations: args.iterations,
        scale: damage_twin::scene::ImageScale::Factor(2),
        mode: args.mode,
        ..TrainingSettings::default()
    };
    let palette = Palette::default();
    let config = RunConfig::interactive(&training, palette, [0.0; 3]);
    let (_, heldout_indices) =
        split_views(&dataset, &config.holdout).map_err(anyhow::Error::msg)?;
    let (eval_scale, eval_mode) = (config.scale, effective_mode(&dataset, config.mode));
    let job = train_job(dataset.clone(), config, JobOptions::headless(None));
    let train_started = Instant::now();
    let mut history = History::default();
    let outcome = drive(job, "training", false, |p| {
        history.record_progress(p, train_started.elapsed().as_secs_f64());
    })?;
    let last_wall = history.last().map_or(0.0, |s| s.wall_s);
    history.record_final(outcome.heldout.as_ref().map(|s| s.psnr), last_wall);

    // 3. Model, renders, metrics, charts.
    let model_path = args.out.join("model.ply");
    damage_twin::splats::ply::write_splats(&model_path, &outcome.splats)
        .with_context(|| format!("writing {}", model_path.display()))?;
    let renders = write_renders(&args.out, &dataset, &outcome.splats, args.renders)?;
    let charts = write_training_charts(&args.out, &history)?;
    let request = EvalRequest {
        indices: heldout_indices,
        scale: eval_scale,
        background: glam::Vec3::ZERO,
        sh_degree: outcome.splats.sh_degree,
        photometric: false,
        half_appearance: false,
        readout: DamageReadout {
            mode: eval_mode,
            ..DamageReadout::for_model(&outcome.splats, palette)
        },
    };
    let damage = evaluate_model(&dataset, &outcome.splats, &request, &mut |_, _| {})?.damage;
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
    let text = serde_json::to_string_pretty(&metrics)?;
    write_atomic(&metrics_path, |w| {
        std::io::Write::write_all(w, text.as_bytes())
    })
    .with_context(|| format!("writing {}", metrics_path.display()))?;
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

/// Renders up to `count` held-out views (every 8th) as the viewer shows them into `renders/`.
fn write_renders(
    out: &Path,
    dataset: &Dataset,
    splats: &damage_twin::splats::Splats,
    count: usize,
) -> anyhow::Result<Vec<PathBuf>> {
    let dir = out.join("renders");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let style = DisplayStyle::default();
    let mut written = Vec::new();
    for index in (0..dataset.views.len()).step_by(8).take(count) {
        let view = &dataset.views[index];
        let path = dir.join(format!("{}.png", view.name.replace('/', "_")));
        render_png(&path, splats, &view.camera, &style)?;
        written.push(path);
    }
    Ok(written)
}
