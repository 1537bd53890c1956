//! `damage-twin study update --run LABEL=METRICS … --out DIR`: survey updates already run with
//! `twin update` (their `surveys/<name>/metrics.json`), gathered into `update-study.json`, a
//! Markdown table and the speed-against-accuracy chart (`.png`, `.svg`). The study itself is
//! `studies::update`.

use std::path::PathBuf;

use anyhow::Context;

use damage_twin::studies::update::{UpdateRow, read_row, update_table, write_update_chart};

use super::write_text;

#[derive(clap::Args, Debug)]
pub struct UpdateStudyArgs {
    /// One update: a label, `=`, and its `metrics.json` (repeatable; in the table's order).
    #[arg(long = "run", required = true)]
    pub runs: Vec<String>,
    /// Training the survey from scratch, seconds (same host and sitting): each row's share.
    #[arg(long)]
    pub from_scratch_seconds: Option<f64>,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: UpdateStudyArgs) -> anyhow::Result<()> {
    let mut rows: Vec<UpdateRow> = Vec::new();
    for run in &args.runs {
        let (label, path) = run
            .split_once('=')
            .with_context(|| format!("--run {run}: expected LABEL=METRICS.JSON"))?;
        rows.push(read_row(label, path.as_ref(), args.from_scratch_seconds)?);
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    write_text(
        &args.out,
        "update-study.json",
        &serde_json::to_string_pretty(&rows)?,
    )?;
    let table = update_table(&rows);
    write_text(&args.out, "update-study.md", &table)?;
    let charts = write_update_chart(&args.out, "update-study", &rows)?;
    print!("{table}");
    for chart in charts {
        println!("wrote {}", chart.display());
    }
    Ok(())
}
