//! `damage-twin study budget DATASET --scene NAME --out DIR`: the Gaussian budget (issue 24 §4)
//! measured on one scene: a full run, `train --budget` at fractions of the full run's final
//! count, and `compact` of the full model. Its rows replace that scene's rows in
//! `DIR/budget-study.json` (other scenes' are kept), and the chart of PSNR against Gaussians
//! (`budget-study.png`, `.svg`) is redrawn from all of them.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context;

use damage_twin::damage::TrainMode;
use damage_twin::damage::setup::RunConfig;
use damage_twin::scene::Dataset;
use damage_twin::studies::budget::chart::write_budget_chart;
use damage_twin::studies::budget::{BudgetConfig, BudgetFile, SceneRun, budget_job};
use damage_twin::train::job::JobOptions;

use super::{read_saved, write_text};
use crate::cli::args::{RunArgs, drive, open_dataset};

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
    #[arg(long, value_parser = crate::cli::args::parse_threads)]
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

pub fn run(args: BudgetArgs) -> anyhow::Result<()> {
    if args.replot {
        let file: BudgetFile = read_saved(&args.out, "budget-study.json")?;
        write_budget_chart(&args.out, "budget-study", &file.rows)?;
        return Ok(());
    }
    let dataset: Arc<Dataset> = Arc::new(open_dataset(&args.dataset, args.run.images.background)?);
    let models_dir = args.out.join("models");
    std::fs::create_dir_all(&models_dir)
        .with_context(|| format!("creating {}", models_dir.display()))?;
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    let config = BudgetConfig {
        scene: args.scene.clone(),
        run: RunConfig {
            mode: TrainMode::Rgb,
            scale: args.run.images.scale,
            iterations: args.iters,
            holdout: args.run.holdout.holdout(),
            sh_degree: args.run.sh_degree,
            seed: args.run.seed,
            background: args.run.images.background,
            random_points: args.run.init_points,
            eval_every: 0,
            ..RunConfig::default()
        },
        budgets: args.budgets.clone(),
        compact: args.compact.clone(),
        compact_iterations: args.compact_iters,
        models_dir,
    };
    let job = budget_job(dataset, config, JobOptions::headless(Some(threads)));
    let outcome = drive(job, "budget study", true, |_| {})?;

    // Merge with the other scenes' rows already in the file.
    let json_path = args.out.join("budget-study.json");
    let mut file: BudgetFile = if damage_twin::scene::files::is_present(&json_path) {
        let bytes = damage_twin::scene::files::read_regular(
            &json_path,
            damage_twin::scene::limits::MAX_PROJECT_JSON_BYTES,
        )?;
        serde_json::from_slice(&bytes)
            .with_context(|| format!("reading {}", json_path.display()))?
    } else {
        BudgetFile::default()
    };
    let (width, height) = outcome.size;
    let scene = SceneRun {
        scene: args.scene.clone(),
        dataset: args.dataset.display().to_string(),
        width,
        height,
        iterations: args.iters,
        compact_iterations: args.compact_iters,
        threads,
    };
    file.merge(scene, outcome.rows);
    let json = serde_json::to_string_pretty(&file)?;
    write_text(&args.out, "budget-study.json", &json)?;
    write_budget_chart(&args.out, "budget-study", &file.rows)?;
    println!("{json}");
    Ok(())
}
