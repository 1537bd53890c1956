//! `damage-twin study mask-noise DATASET --out DIR`: the error-mitigation study. Trains the twin
//! on deliberately corrupted masks at each rate, in each mode, and writes `study.json`,
//! `study.csv`, `study.md` and the chart (`study.svg`, `study.png`).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

use damage_twin::damage::TrainMode;
use damage_twin::damage::refine::RefineConfig;
use damage_twin::damage::setup::RunConfig;
use damage_twin::scene::ImageScale;
use damage_twin::studies::mask_noise::chart::{study_csv, study_table, write_study_chart};
use damage_twin::studies::mask_noise::{NoiseModel, StudyConfig, StudyEvent, StudyRow, run_study};

use super::{read_saved, write_text};
use crate::cli::args::{HoldoutArgs, open_dataset, palette, parse_scale, print_line};

#[derive(clap::Args, Debug)]
pub struct MaskNoiseArgs {
    /// A dataset with masks (a synthetic survey's truth/masks is the clean reference).
    pub dataset: PathBuf,
    #[arg(long)]
    pub out: PathBuf,
    /// Error per training view as a fraction of its damage area (--noise area), or the
    /// fraction of training views whose masks are corrupted (--noise views).
    #[arg(long, value_delimiter = ',', default_value = "0,0.1,0.2,0.4,0.8")]
    pub rates: Vec<f32>,
    /// area: every view, error = rate × its damage area per class (the paper's Figure 11);
    /// views: a fraction of the views, a few blobs each (synth --mask-noise).
    #[arg(long, default_value = "area")]
    pub noise: NoiseModel,
    /// Modes to train in.
    #[arg(long, value_delimiter = ',', default_value = "label,overlay")]
    pub modes: Vec<TrainMode>,
    /// Iterations per run.
    #[arg(long, default_value_t = 1200)]
    pub iters: u32,
    /// Steps of the full-resolution fine-tune (hierarchical refinement) of each label-mode twin,
    /// scored at the photos' resolution (0: none). Cracks are below the coarse pixel grid.
    #[arg(long, default_value_t = 1000)]
    pub fine_iters: u32,
    /// Image scale (4: 240×135 for the 960×540 demo building).
    #[arg(long, default_value = "4", value_parser = parse_scale)]
    pub scale: ImageScale,
    #[command(flatten)]
    pub holdout: HoldoutArgs,
    /// Weight of the label loss (label mode).
    #[arg(long, default_value_t = RunConfig::default().label_weight)]
    pub label_weight: f32,
    /// The fraction of the run during which the label loss shapes the geometry; after it only
    /// the label logits follow the masks (label mode; default: the whole run).
    #[arg(long, value_name = "FRACTION")]
    pub label_geometry_until: Option<f32>,
    /// Weight of damage pixels in the label cross-entropy (label mode).
    #[arg(long, default_value_t = RunConfig::default().label_pos_weight)]
    pub label_pos_weight: f32,
    /// The same for the full-resolution fine-tune (default: the whole fine-tune).
    #[arg(long, value_name = "FRACTION")]
    pub fine_label_geometry_until: Option<f32>,
    /// Weight of damage pixels in the full-resolution fine-tune's label cross-entropy (default:
    /// the refinement's).
    #[arg(long, default_value_t = RefineConfig::default().label_pos_weight)]
    pub fine_label_pos_weight: f32,
    /// Class colour override for overlay mode, class=r,g,b (repeatable).
    #[arg(long = "colour")]
    pub colours: Vec<String>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long, value_parser = crate::cli::args::parse_threads)]
    pub threads: Option<usize>,
    /// Train nothing: redraw the chart and tables from an existing `--out DIR/study.json`.
    #[arg(long)]
    pub replot: bool,
}

#[derive(serde::Deserialize)]
struct SavedStudy {
    rows: Vec<StudyRow>,
}

/// Writes the CSV, Markdown table and chart of `rows` into `dir`.
fn write_reports(dir: &std::path::Path, rows: &[StudyRow]) -> anyhow::Result<Vec<PathBuf>> {
    write_text(dir, "study.csv", &study_csv(rows))?;
    write_text(dir, "study.md", &study_table(rows))?;
    Ok(write_study_chart(dir, "study", rows)?)
}

#[derive(Serialize)]
struct StudyFile<'a> {
    dataset: &'a std::path::Path,
    noise: NoiseModel,
    rates: &'a [f32],
    modes: &'a [TrainMode],
    iterations: u32,
    fine_iterations: u32,
    label_weight: f32,
    label_geometry_until: Option<f32>,
    fine_label_geometry_until: Option<f32>,
    label_pos_weight: f32,
    fine_label_pos_weight: f32,
    scale: ImageScale,
    seed: u64,
    seconds: f64,
    rows: &'a [StudyRow],
}

pub fn run(args: MaskNoiseArgs) -> anyhow::Result<()> {
    if args.replot {
        let saved: SavedStudy = read_saved(&args.out, "study.json")?;
        let charts = write_reports(&args.out, &saved.rows)?;
        eprintln!(
            "redrew {} rows into {}",
            saved.rows.len(),
            charts[0].display()
        );
        return Ok(());
    }
    if args.rates.iter().any(|r| !(0.0..=1.0).contains(r)) {
        anyhow::bail!("rates must lie in [0, 1], got {:?}", args.rates);
    }
    let started = Instant::now();
    let dataset = open_dataset(&args.dataset, Vec3::ZERO)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let config = StudyConfig {
        rates: args.rates.clone(),
        modes: args.modes.clone(),
        run: RunConfig {
            palette: palette(&args.colours)?,
            scale: args.scale,
            iterations: args.iters,
            holdout: args.holdout.holdout(),
            seed: args.seed,
            label_weight: args.label_weight,
            label_geometry_until: args.label_geometry_until,
            label_pos_weight: args.label_pos_weight,
            ..RunConfig::default()
        },
        noise: args.noise,
        noise_seed: args.seed,
        threads: args.threads,
        fine_iterations: args.fine_iters,
        fine_label_geometry_until: args.fine_label_geometry_until,
        fine_label_pos_weight: args.fine_label_pos_weight,
    };
    let runs = args.rates.len() * args.modes.len();
    let bar = ProgressBar::new((runs as u64) * u64::from(args.iters)).with_style(
        ProgressStyle::with_template("{bar:30} {percent:>3}% {elapsed} ETA {eta} | {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let iters = u64::from(args.iters);
    let rows = run_study(&dataset, &config, &mut |event| match event {
        StudyEvent::RunStarted {
            run,
            runs,
            mode,
            rate,
        } => bar.set_message(format!("run {}/{runs}: {mode} mode, rate {rate}", run + 1)),
        StudyEvent::Step { run, step, .. } => bar.set_position(run as u64 * iters + u64::from(step)),
        StudyEvent::FineStarted { rate } => {
            bar.set_message(format!("label mode, rate {rate}: fine-tune at full resolution"))
        }
        StudyEvent::FineFailed { rate, error } => {
            print_line(&bar, format!("rate {rate}: no fine-tune rows: {error}"))
        }
        StudyEvent::RunFinished { rows, .. } => {
            for r in rows {
                let line = format!(
                    "{} {} rate {:.2} {:<9} input IoU {:.3} → twin IoU {:.3} (train views), {:.3} (held-out); errors corrected {:.1} % (cut-out {:.1} %, added {:.1} %; clean twin {:.1} %), introduced {:.2} %",
                    r.mode,
                    r.stage,
                    r.rate,
                    r.class,
                    r.input_iou,
                    r.twin_iou_train,
                    r.twin_iou_heldout,
                    100.0 * r.errors_corrected,
                    100.0 * r.missed_corrected,
                    100.0 * r.added_corrected,
                    100.0 * r.clean_twin_corrected,
                    100.0 * r.errors_introduced
                );
                print_line(&bar, line);
            }
        }
    })
    .map_err(anyhow::Error::msg)?;
    bar.finish_and_clear();

    let seconds = started.elapsed().as_secs_f64();
    let file = StudyFile {
        dataset: &args.dataset,
        noise: args.noise,
        rates: &args.rates,
        modes: &args.modes,
        iterations: args.iters,
        fine_iterations: args.fine_iters,
        label_weight: args.label_weight,
        label_geometry_until: args.label_geometry_until,
        fine_label_geometry_until: args.fine_label_geometry_until,
        label_pos_weight: args.label_pos_weight,
        fine_label_pos_weight: args.fine_label_pos_weight,
        scale: args.scale,
        seed: args.seed,
        seconds,
        rows: &rows,
    };
    write_text(
        &args.out,
        "study.json",
        &serde_json::to_string_pretty(&file)?,
    )?;
    let charts = write_reports(&args.out, &rows)?;
    eprintln!(
        "study done in {seconds:.0} s: {} rows; wrote study.json, study.csv, study.md and {}",
        rows.len(),
        charts
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}
