//! `damage-twin study stability DATASET --out DIR`: where the twin holds and where it breaks
//! (issue 24 §3; the suite is `studies::stability`). Writes `stability-study.json`, `.csv`,
//! `.md` and the chart (`.png`, `.svg`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use damage_twin::scene::ImageScale;
use damage_twin::studies::stability::chart::write_stability_chart;
use damage_twin::studies::stability::table::{stability_csv, stability_table};
use damage_twin::studies::stability::{StabilityConfig, StabilityRow, run_stability};

use super::{read_saved, write_text};
use crate::cli::args::{open_dataset, parse_scale};

#[derive(clap::Args, Debug)]
pub struct StabilityArgs {
    /// A synthetic survey of the demo building (`synth --out D`, then D/survey-1).
    pub dataset: PathBuf,
    #[arg(long)]
    pub out: PathBuf,
    /// Iterations per run (docs/DAMAGE.md's runs use 3,000).
    #[arg(long, default_value_t = 3000)]
    pub iters: u32,
    /// The baseline's training scale.
    #[arg(long, default_value = "4", value_parser = parse_scale)]
    pub scale: ImageScale,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long, value_parser = crate::cli::args::parse_threads)]
    pub threads: Option<usize>,
    /// Training-view counts (the baseline trains on all of them).
    #[arg(long, value_delimiter = ',', default_value = "30,15,8")]
    pub views: Vec<usize>,
    /// Pose noise of the training cameras, degrees (with proportional translation noise).
    #[arg(long, value_delimiter = ',', default_value = "0.25,0.5,1,2")]
    pub pose_noise: Vec<f32>,
    /// Training downscale factors besides the baseline's.
    #[arg(long, value_delimiter = ',', default_value = "8,2")]
    pub scales: Vec<u32>,
    /// Skip the textureless axis (it regenerates the dataset twice at the training size).
    #[arg(long)]
    pub no_textureless: bool,
    /// The mask-noise study whose label-mode rows make the mask_noise axis.
    #[arg(long, default_value = "docs/figures/mask-noise-study.json")]
    pub mask_noise_json: PathBuf,
    /// Train nothing: redraw the chart and tables from an existing `--out DIR`'s
    /// stability-study.json.
    #[arg(long)]
    pub replot: bool,
}

/// The rows of a saved stability-study.json.
#[derive(Deserialize)]
struct SavedStudy {
    rows: Vec<StabilityRow>,
}

#[derive(Serialize)]
struct StudyFile<'a> {
    dataset: String,
    iterations: u32,
    scale: ImageScale,
    seed: u64,
    threads: usize,
    seconds: f64,
    /// Where the mask_noise rows come from (their own iterations and settings).
    mask_noise_source: Option<String>,
    rows: &'a [StabilityRow],
}

/// Writes the CSV, the Markdown table and the chart of `rows` into `out`.
fn write_reports(out: &Path, rows: &[StabilityRow]) -> anyhow::Result<()> {
    write_text(out, "stability-study.csv", &stability_csv(rows))?;
    write_text(out, "stability-study.md", &stability_table(rows))?;
    write_stability_chart(out, "stability-study", rows)?;
    Ok(())
}

pub fn run(args: StabilityArgs) -> anyhow::Result<()> {
    if args.replot {
        let saved: SavedStudy = read_saved(&args.out, "stability-study.json")?;
        write_reports(&args.out, &saved.rows)?;
        eprintln!("redrew {} rows in {}", saved.rows.len(), args.out.display());
        return Ok(());
    }
    let started = Instant::now();
    let dataset = open_dataset(&args.dataset, glam::Vec3::ZERO)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    let config = StabilityConfig {
        iterations: args.iters,
        scale: args.scale,
        seed: args.seed,
        threads,
        views: args.views.clone(),
        pose_noise: args.pose_noise.clone(),
        scales: args.scales.clone(),
        textureless: !args.no_textureless,
        work_dir: args.out.join("data"),
        mask_noise_json: args.mask_noise_json.clone(),
    };
    let outcome = run_stability(&dataset, &config, &mut |line| eprintln!("{line}"))
        .map_err(anyhow::Error::msg)?;
    let rows = &outcome.rows;

    let file = StudyFile {
        dataset: args.dataset.display().to_string(),
        iterations: args.iters,
        scale: args.scale,
        seed: args.seed,
        threads,
        seconds: started.elapsed().as_secs_f64(),
        mask_noise_source: outcome.mask_noise_source.clone(),
        rows,
    };
    let json = serde_json::to_string_pretty(&file)?;
    write_text(&args.out, "stability-study.json", &json)?;
    write_reports(&args.out, rows)?;
    println!("{}", stability_table(rows));
    Ok(())
}
