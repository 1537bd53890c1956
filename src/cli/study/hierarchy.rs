//! `damage-twin study hierarchy DATASET --out DIR`: full high-resolution training against the
//! hierarchy (coarse, coarse + fine-tune, coarse + retrain), each timed and scored at high
//! resolution on the held-out views. Writes `hierarchy-study.json`, `.csv`, `.md` and the
//! speed-against-accuracy chart (`.png`, `.svg`). The study itself is `studies::hierarchy`.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use glam::Vec3;
use serde::Serialize;

use damage_twin::scene::ImageScale;
use damage_twin::studies::hierarchy::table::{
    hierarchy_csv, hierarchy_table, write_hierarchy_chart,
};
use damage_twin::studies::hierarchy::{HierarchyRow, Method, default_config, hierarchy_job};
use damage_twin::train::job::JobOptions;

use super::write_text;
use crate::cli::args::{HoldoutArgs, drive, open_dataset, palette, parse_scale};

#[derive(clap::Args, Debug)]
pub struct HierarchyArgs {
    /// A dataset with damage masks (the demo building's survey-1).
    pub dataset: PathBuf,
    #[arg(long)]
    pub out: PathBuf,
    /// Methods to run: full, coarse, finetune, retrain.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "coarse,finetune,retrain,full"
    )]
    pub methods: Vec<String>,
    /// The coarse twin's scale (4: 240×135 of the 960×540 demo).
    #[arg(long, default_value = "4", value_parser = parse_scale)]
    pub coarse_scale: ImageScale,
    #[arg(long, default_value_t = 3000)]
    pub coarse_iters: u32,
    /// "High resolution": the full run's, the refinements' and the scores' scale.
    #[arg(long, default_value = "1", value_parser = parse_scale)]
    pub fine_scale: ImageScale,
    #[arg(long, default_value_t = 3000)]
    pub full_iters: u32,
    #[arg(long, default_value_t = 1000)]
    pub refine_iters: u32,
    #[command(flatten)]
    pub holdout: HoldoutArgs,
    /// Class colour override for overlay mode, class=r,g,b (repeatable).
    #[arg(long = "colour")]
    pub colours: Vec<String>,
    #[arg(long, default_value = "label")]
    pub mode: damage_twin::damage::TrainMode,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long, value_parser = crate::cli::args::parse_threads)]
    pub threads: Option<usize>,
}

#[derive(Serialize)]
struct StudyFile<'a> {
    dataset: &'a std::path::Path,
    /// Width and height of "high resolution".
    fine_size: (u32, u32),
    coarse_scale: ImageScale,
    coarse_iterations: u32,
    fine_scale: ImageScale,
    full_iterations: u32,
    refine_iterations: u32,
    threads: usize,
    seconds: f64,
    rows: &'a [HierarchyRow],
}

fn method(name: &str) -> anyhow::Result<Method> {
    Ok(match name.trim() {
        "full" => Method::Full,
        "coarse" => Method::Coarse,
        "finetune" => Method::Finetune,
        "retrain" => Method::Retrain,
        other => anyhow::bail!("unknown method {other:?}: use full, coarse, finetune, retrain"),
    })
}

pub fn run(args: HierarchyArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let dataset = Arc::new(open_dataset(&args.dataset, Vec3::ZERO)?);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let mut config = default_config(palette(&args.colours)?);
    config.methods = args
        .methods
        .iter()
        .map(|m| method(m))
        .collect::<anyhow::Result<_>>()?;
    config.run.mode = args.mode;
    config.run.holdout = args.holdout.holdout();
    config.run.seed = args.seed;
    config.coarse_scale = args.coarse_scale;
    config.coarse_iterations = args.coarse_iters;
    config.fine_scale = args.fine_scale;
    config.full_iterations = args.full_iters;
    config.refine.iterations = args.refine_iters;
    config.refine.holdout = config.run.holdout.clone();
    config.refine.seed = args.seed;
    config.refine.select.mode = args.mode;
    config.refine.select.palette = config.run.palette;
    let job = hierarchy_job(dataset, config, JobOptions::headless(args.threads));
    let outcome = drive(job, "hierarchy study", false, |_| {})?;
    let rows = &outcome.rows;
    let file = StudyFile {
        dataset: &args.dataset,
        fine_size: outcome.fine_size,
        coarse_scale: args.coarse_scale,
        coarse_iterations: args.coarse_iters,
        fine_scale: args.fine_scale,
        full_iterations: args.full_iters,
        refine_iterations: args.refine_iters,
        threads: args.threads.unwrap_or_else(rayon::current_num_threads),
        seconds: started.elapsed().as_secs_f64(),
        rows,
    };
    write_text(
        &args.out,
        "hierarchy-study.json",
        &serde_json::to_string_pretty(&file)?,
    )?;
    write_text(&args.out, "hierarchy-study.csv", &hierarchy_csv(rows))?;
    let table = hierarchy_table(rows);
    write_text(&args.out, "hierarchy-study.md", &table)?;
    write_hierarchy_chart(&args.out, "hierarchy-study", rows)?;
    println!("{table}");
    Ok(())
}
