//! `damage-twin study budget DATASET --scene NAME --out DIR`: the Gaussian budget (issue 24 §4)
//! measured on one scene: a full run, `train --budget` at fractions of the full run's final
//! count, and `compact` of the full model. Its rows replace that scene's rows in
//! `DIR/budget-study.json` (other scenes' are kept), and the chart of PSNR against Gaussians
//! (`budget-study.png`, `.svg`) is redrawn from all of them.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use damage_twin::damage::TrainMode;
use damage_twin::damage::setup::{RunConfig, train_job};
use damage_twin::report::budget_chart::{BudgetRow, write_budget_chart};
use damage_twin::scene::Dataset;
use damage_twin::splats::Splats;
use damage_twin::train::job::JobOptions;
use damage_twin::train::views::split_views;

use super::{read_saved, write_text};
use crate::cli::args::{RunArgs, drive, open_dataset};
use crate::cli::compact::{Finetune, compact_model, heldout_psnr};

#[derive(clap::Args, Debug)]
pub struct BudgetArgs {
    pub dataset: PathBuf,
    /// The scene's name in the rows (`demo`, `lego`).
    #[arg(long)]
    pub scene: String,
    /// Folder of budget-study.json and the chart; the models go to DIR/models/.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, default_value_t = 3000)]
    pub iters: u32,
    #[command(flatten)]
    pub run: RunArgs,
    /// Training threads (default: all cores, or RAYON_NUM_THREADS).
    #[arg(long)]
    pub threads: Option<usize>,
    /// `train --budget` runs, as fractions of the full run's final count.
    #[arg(long, value_delimiter = ',', default_value = "0.5,0.3")]
    pub budgets: Vec<f64>,
    /// `compact` runs of the full model, as fractions of its count.
    #[arg(long, value_delimiter = ',', default_value = "0.5")]
    pub compact: Vec<f64>,
    #[arg(long, default_value_t = 500)]
    pub compact_iters: u32,
    /// Train nothing: redraw the chart from an existing `--out DIR/budget-study.json` (rows of
    /// several studies merged there, say).
    #[arg(long)]
    pub replot: bool,
}

/// How one scene was measured.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct SceneRun {
    scene: String,
    dataset: String,
    width: u32,
    height: u32,
    iterations: u32,
    compact_iterations: u32,
    threads: usize,
}

#[derive(Debug, Default, Serialize, Deserialize)]
struct StudyFile {
    #[serde(default)]
    scenes: Vec<SceneRun>,
    #[serde(default)]
    rows: Vec<BudgetRow>,
}

fn percent(fraction: f64) -> String {
    format!("{:.0}%", fraction * 100.0)
}

/// Writes `splats` to DIR/models/NAME.ply (NAME made a file name) and returns its size.
fn save(out: &Path, name: &str, splats: &Splats) -> anyhow::Result<u64> {
    let file: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    let path = out.join("models").join(format!("{file}.ply"));
    damage_twin::scene::ply::write_splats(&path, splats)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(std::fs::metadata(&path)?.len())
}

pub fn run(args: BudgetArgs) -> anyhow::Result<()> {
    if args.replot {
        let file: StudyFile = read_saved(&args.out, "budget-study.json")?;
        write_budget_chart(&args.out, "budget-study", &file.rows)?;
        return Ok(());
    }
    let dataset: Arc<Dataset> = Arc::new(open_dataset(&args.dataset, args.run.images.background)?);
    let holdout = args.run.holdout.holdout();
    let (train_idx, test_idx) = split_views(&dataset, &holdout).map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(args.out.join("models"))
        .with_context(|| format!("creating {}", args.out.join("models").display()))?;
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    let base = RunConfig {
        mode: TrainMode::Rgb,
        scale: args.run.images.scale,
        iterations: args.iters,
        holdout,
        sh_degree: args.run.sh_degree,
        seed: args.run.seed,
        background: args.run.images.background,
        random_points: args.run.init_points,
        eval_every: 0,
        ..RunConfig::default()
    };
    let psnr = |splats: &Splats| {
        heldout_psnr(
            &dataset,
            splats,
            &test_idx,
            args.run.images.scale,
            args.run.images.background,
        )
    };
    let mut rows = Vec::new();
    let mut train = |method: String, budget: Option<usize>| -> anyhow::Result<_> {
        eprintln!("{}: {method}", args.scene);
        let config = RunConfig {
            budget,
            ..base.clone()
        };
        let job = train_job(
            dataset.clone(),
            config,
            JobOptions::headless(threads.into()),
        );
        let outcome = drive(job, &method, true, |_| {})?;
        let name = format!("{}-{}", args.scene, method);
        let row = BudgetRow {
            scene: args.scene.clone(),
            psnr: psnr(&outcome.splats)?,
            gaussians: outcome.splats.len(),
            bytes: save(&args.out, &name, &outcome.splats)?,
            seconds: outcome.seconds,
            method,
        };
        eprintln!("  {row:?}");
        rows.push(row.clone());
        Ok((outcome.splats, row))
    };
    let (full, full_row) = train("full".into(), None)?;
    for &fraction in &args.budgets {
        let budget = (full.len() as f64 * fraction).round().max(1.0) as usize;
        train(format!("budget {}", percent(fraction)), Some(budget))?;
    }
    for &fraction in &args.compact {
        let method = format!("compact {}", percent(fraction));
        eprintln!("{}: {method}", args.scene);
        let keep = (full.len() as f64 * fraction).round().max(1.0) as usize;
        let finetune = Finetune {
            iterations: args.compact_iters,
            scale: args.run.images.scale,
            background: args.run.images.background,
            seed: args.run.seed,
            threads: Some(threads),
            quiet: true,
        };
        let compacted = compact_model(
            &dataset,
            (*full).clone(),
            &train_idx,
            keep,
            &finetune,
            &mut |_| Ok(()),
        )?;
        let name = format!("{}-{}", args.scene, method);
        let row = BudgetRow {
            scene: args.scene.clone(),
            psnr: psnr(&compacted.splats)?,
            gaussians: compacted.splats.len(),
            bytes: save(&args.out, &name, &compacted.splats)?,
            seconds: full_row.seconds + compacted.seconds,
            method,
        };
        eprintln!("  {row:?}");
        rows.push(row);
    }

    // Merge with the other scenes' rows already in the file.
    let json_path = args.out.join("budget-study.json");
    let mut file: StudyFile = match std::fs::read_to_string(&json_path) {
        Ok(text) => serde_json::from_str(&text)
            .with_context(|| format!("reading {}", json_path.display()))?,
        Err(_) => StudyFile::default(),
    };
    file.rows.retain(|r| r.scene != args.scene);
    file.rows.extend(rows);
    file.scenes.retain(|s| s.scene != args.scene);
    let first = &dataset.views[train_idx[0]].camera.intrinsics;
    let (width, height) = args.run.images.scale.apply(first.width, first.height);
    file.scenes.push(SceneRun {
        scene: args.scene.clone(),
        dataset: args.dataset.display().to_string(),
        width,
        height,
        iterations: args.iters,
        compact_iterations: args.compact_iters,
        threads,
    });
    let json = serde_json::to_string_pretty(&file)?;
    write_text(&args.out, "budget-study.json", &json)?;
    write_budget_chart(&args.out, "budget-study", &file.rows)?;
    println!("{json}");
    Ok(())
}
