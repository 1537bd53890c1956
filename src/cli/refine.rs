//! `damage-twin refine MODEL.ply DATASET --out DIR`: hierarchical refinement of a coarse twin's
//! damage (`damage::refine`). Writes `model.ply`, `selection.json`, `hulls/<view>.png`,
//! `metrics.json` and a before/after render of one held-out view with the damage layer.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use serde::Serialize;

use damage_twin::damage::display::{DisplayStyle, render_png, save_png};
use damage_twin::damage::evaluate::DamageReadout;
use damage_twin::damage::hull_picture::hull_picture;
use damage_twin::damage::refine::{RefineConfig, RefineOutcome, Strategy, refine_job};
use damage_twin::damage::select::{SelectConfig, Validation};
use damage_twin::damage::{DamageClass, Palette, TrainMode};
use damage_twin::scene::atomic::write_atomic;
use damage_twin::scene::run_folder::RunFolder;
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::train::focus::hulls::HullConfig;

use super::args::{
    HoldoutArgs, ImageArgs, JobArgs, drive, open_dataset, palette, parse_scale, read_model,
};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The coarse twin (a label-mode or overlay-mode model).
    pub model: PathBuf,
    /// The dataset it was trained on (its masks validate the selection).
    pub dataset: PathBuf,
    #[arg(long)]
    pub out: PathBuf,
    /// Damage classes to refine.
    #[arg(long, value_delimiter = ',', default_value = "crack,spalling,rebar")]
    pub classes: Vec<String>,
    /// finetune (the selection as it is) or retrain (with density control in the selection).
    #[arg(long, default_value = "finetune")]
    pub strategy: Strategy,
    // `--scale`: the high resolution the selection is refined at.
    #[command(flatten)]
    pub images: ImageArgs,
    #[arg(long, default_value_t = 1000)]
    pub iters: u32,
    /// The renderer that trains: cpu, gpu or auto (see `train --backend`).
    #[arg(long, default_value = "cpu")]
    pub backend: damage_twin::train::backend_choice::Backend,
    /// Hull dilation in pixels at the refinement scale.
    #[arg(long, default_value_t = HullConfig::default().dilate_px)]
    pub dilate: f32,
    /// Neighbours added around each validated damage Gaussian.
    #[arg(long, default_value_t = SelectConfig::default().min_neighbours)]
    pub min_neighbours: usize,
    /// How candidates are checked against the masks: lift (blending-weight majority), vote
    /// (centre inside the mask in enough views) or none.
    #[arg(long, default_value = "lift")]
    pub validation: Validation,
    /// One hull per view (the paper) instead of one per connected damage region.
    #[arg(long)]
    pub hull_per_view: bool,
    /// The resolution of the masks the selection is validated against (`--scale` is the high
    /// resolution the selection is refined at).
    #[arg(long, default_value = "4", value_parser = parse_scale)]
    pub select_scale: ImageScale,
    /// How damage is read: label or overlay (default: label when the model has label channels).
    #[arg(long)]
    pub mode: Option<TrainMode>,
    /// Class colour override for overlay mode, class=r,g,b (repeatable).
    #[arg(long = "colour")]
    pub colours: Vec<String>,
    #[command(flatten)]
    pub holdout: HoldoutArgs,
    /// Weight of damage pixels in the label cross-entropy (label mode).
    #[arg(long, default_value_t = RefineConfig::default().label_pos_weight)]
    pub label_pos_weight: f32,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub job: JobArgs,
}

#[derive(Serialize)]
struct SelectionFile<'a> {
    filtered: usize,
    validated: usize,
    selected: usize,
    seconds: &'a damage_twin::damage::select::SelectTimes,
    /// Stable ids (`id` PLY property) of the selected Gaussians of the input model.
    selected_ids: Vec<u64>,
    validated_ids: Vec<u64>,
}

/// `metrics.json`: the report, with the held-out PSNR outside the hulls also at the top level
/// (the figure that says the frozen rest was left alone).
#[derive(Serialize)]
struct MetricsFile<'a> {
    psnr_outside_hulls_before: Option<f64>,
    psnr_outside_hulls_after: Option<f64>,
    #[serde(flatten)]
    report: &'a damage_twin::damage::refine::RefineReport,
}

pub fn parse_classes(names: &[String]) -> anyhow::Result<Vec<DamageClass>> {
    names
        .iter()
        .map(|n| {
            DamageClass::from_id(n.trim()).with_context(|| {
                format!("unknown damage class {n:?}: use crack, spalling or rebar")
            })
        })
        .collect()
}

/// Every file or folder a refinement may write into its output folder: none of them is carried
/// over from an earlier refinement there (scene::run_folder).
const REFINE_OUTPUTS: &[&str] = &[
    "hulls",
    "before_*",
    "after_*",
    "selection.json",
    "model.ply",
    "metrics.json",
];

pub fn run(args: Args) -> anyhow::Result<()> {
    let model = Arc::new(read_model(&args.model)?);
    let dataset = Arc::new(open_dataset(&args.dataset, args.images.background)?);
    // Staged beside the output folder and swapped in whole (scene::run_folder): a kill leaves
    // the previous refinement's files or this one's, and an unwritable place fails now.
    let outputs = RunFolder::begin(&args.out, REFINE_OUTPUTS)
        .with_context(|| format!("preparing output folder {}", args.out.display()))?;
    std::fs::create_dir_all(outputs.path("hulls"))
        .with_context(|| format!("creating {}", args.out.join("hulls").display()))?;
    // An overlay model's own colours (saved with it) win over --colour.
    let readout = DamageReadout::for_model(&model, palette(&args.colours)?);
    let palette = readout.palette;
    let mode = args.mode.unwrap_or(readout.mode);
    let config = RefineConfig {
        select: SelectConfig {
            classes: parse_classes(&args.classes)?,
            mode,
            palette,
            colour_tolerance: readout.tolerance,
            validation: args.validation,
            min_neighbours: args.min_neighbours,
            ..SelectConfig::default()
        },
        hulls: HullConfig {
            dilate_px: args.dilate,
            per_region: !args.hull_per_view,
            ..HullConfig::default()
        },
        strategy: args.strategy,
        scale: args.images.scale,
        select_scale: args.select_scale,
        iterations: args.iters,
        holdout: args.holdout.holdout(),
        background: args.images.background,
        seed: args.seed,
        label_pos_weight: args.label_pos_weight,
        backend: args.backend,
        ..RefineConfig::default()
    };
    let job = refine_job(dataset.clone(), model.clone(), config, args.job.options());
    let outcome = drive(job, "refinement", args.job.quiet, |_| {})?;
    write_outputs(
        outputs.staging(),
        &dataset,
        &model,
        &outcome,
        args.images.scale,
        palette,
    )?;
    outputs
        .commit()
        .with_context(|| format!("replacing {}", args.out.display()))?;
    let json = serde_json::to_string_pretty(&outcome.report)?;
    println!("{json}");
    Ok(())
}

fn write_text(path: &Path, text: &str) -> anyhow::Result<()> {
    write_atomic(path, |w| std::io::Write::write_all(w, text.as_bytes()))
        .with_context(|| format!("writing {}", path.display()))
}

/// Hull pictures, renders, selection, metrics and model; the metrics last.
fn write_outputs(
    out: &Path,
    dataset: &Dataset,
    input: &damage_twin::splats::Splats,
    outcome: &RefineOutcome,
    scale: ImageScale,
    palette: Palette,
) -> anyhow::Result<()> {
    let report = &outcome.report;
    for view in &report.views {
        let photo = dataset.load_view(view.index, scale)?;
        let path = out
            .join("hulls")
            .join(format!("{}.png", view.view.replace('/', "_")));
        save_png(&path, &hull_picture(&photo.image, &view.union()))?;
    }
    if let Some(v) = report.views.iter().find(|v| v.heldout && v.hull_count > 0) {
        let camera = dataset.view_camera(v.index, scale)?;
        let style = DisplayStyle {
            damage: damage_twin::damage::layer::DamageLayer {
                colours: DamageClass::ALL.map(|c| palette.colour(c)),
                ..Default::default()
            },
            ..DisplayStyle::default()
        };
        let stem = v.view.replace('/', "_");
        render_png(
            &out.join(format!("before_{stem}.png")),
            input,
            &camera,
            &style,
        )?;
        render_png(
            &out.join(format!("after_{stem}.png")),
            &outcome.splats,
            &camera,
            &style,
        )?;
    }
    let ids = |list: &[u32]| list.iter().map(|&g| input.meta.ids[g as usize]).collect();
    let selection = SelectionFile {
        filtered: outcome.selection.filtered.len(),
        validated: outcome.selection.validated.len(),
        selected: outcome.selection.selected.len(),
        seconds: &outcome.selection.seconds,
        selected_ids: ids(&outcome.selection.selected),
        validated_ids: ids(&outcome.selection.validated),
    };
    write_text(
        &out.join("selection.json"),
        &serde_json::to_string_pretty(&selection)?,
    )?;
    let model_path = out.join("model.ply");
    damage_twin::splats::ply::write_splats(&model_path, &outcome.splats)
        .with_context(|| format!("writing {}", model_path.display()))?;
    let metrics = MetricsFile {
        psnr_outside_hulls_before: report.before.psnr_outside_hulls,
        psnr_outside_hulls_after: report.after.psnr_outside_hulls,
        report,
    };
    write_text(
        &out.join("metrics.json"),
        &serde_json::to_string_pretty(&metrics)?,
    )
}
