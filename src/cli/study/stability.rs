//! `damage-twin study stability DATASET --out DIR`: where the twin holds and where it breaks
//! (issue 24 §3). Each axis moves alone from a baseline label-mode run on the demo building:
//! fewer training views, noisy training poses, the training scale, a textureless building (the
//! dataset regenerated with `synth --component-colours` at the training size, beside a textured
//! copy made the same way), and mask noise (linked from the mask-noise study's label-mode rows).
//! Writes `stability-study.json`, `.csv`, `.md` and the chart (`.png`, `.svg`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use damage_twin::damage::TrainMode;
use damage_twin::damage::setup::RunConfig;
use damage_twin::damage::stability::{Perturbation, StabilityRow, stability_run};
use damage_twin::report::stability_chart::write_stability_chart;
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::synth::params::SynthParams;
use damage_twin::train::views::{Holdout, split_views};

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
    #[arg(long)]
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

/// The parts of `truth/manifest.ron` this study reads.
#[derive(Deserialize)]
struct Manifest {
    params: SynthParams,
}

/// The mask-noise study's rows this study reads.
#[derive(Deserialize)]
struct MaskNoiseFile {
    iterations: u32,
    rows: Vec<MaskNoiseRow>,
}

#[derive(Deserialize)]
struct MaskNoiseRow {
    mode: TrainMode,
    rate: f64,
    class: String,
    twin_iou_heldout: f64,
    gaussians: usize,
    train_seconds: f64,
    heldout_psnr: f64,
}

/// Writes the CSV, the Markdown table and the chart of `rows` into `out`.
fn write_reports(out: &Path, rows: &[StabilityRow]) -> anyhow::Result<()> {
    write_text(out, "stability-study.csv", &csv(rows))?;
    write_text(out, "stability-study.md", &table(rows))?;
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
    // Read before any training, so a dataset that cannot be regenerated fails now.
    let synth_params = if args.no_textureless {
        None
    } else {
        Some(synth_params(&args.dataset)?)
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    let base = RunConfig {
        mode: TrainMode::Label,
        scale: args.scale,
        iterations: args.iters,
        holdout: Holdout::Auto { every: 8 },
        seed: args.seed,
        eval_every: 0,
        ..RunConfig::default()
    };
    let baseline_factor = match args.scale {
        ImageScale::Factor(f) => f,
        _ => anyhow::bail!("--scale must be a factor (1, 2, 4, 8) for the scale axis"),
    };
    let mut rows: Vec<StabilityRow> = Vec::new();
    let measure = |dataset: &Dataset,
                   config: &RunConfig,
                   perturbation: Perturbation,
                   axis: &str,
                   value: f64|
     -> anyhow::Result<StabilityRow> {
        eprintln!("{axis} = {value} …");
        let row = stability_run(dataset, config, perturbation, axis, value, Some(threads))
            .map_err(anyhow::Error::msg)?;
        eprintln!(
            "  PSNR {:.2} dB, IoU {:?}, {} Gaussians, {:.0} s",
            row.psnr, row.iou, row.gaussians, row.seconds
        );
        Ok(row)
    };

    // The baseline stands in each axis at its own setting.
    let baseline = measure(&dataset, &base, Perturbation::None, "baseline", 0.0)?;
    let training_views = split_views(&dataset, &base.holdout)
        .map_err(anyhow::Error::msg)?
        .0
        .len();
    let at = |axis: &str, value: f64| StabilityRow {
        axis: axis.to_string(),
        value,
        ..baseline.clone()
    };
    rows.push(at("views", training_views as f64));
    rows.push(at("pose_noise", 0.0));
    rows.push(at("scale", f64::from(baseline_factor)));
    for &n in args.views.iter().filter(|&&n| n < training_views) {
        rows.push(measure(
            &dataset,
            &base,
            Perturbation::Views(n),
            "views",
            n as f64,
        )?);
    }
    for &degrees in &args.pose_noise {
        let noise = Perturbation::PoseNoise {
            degrees,
            seed: args.seed ^ 0x9053,
        };
        rows.push(measure(
            &dataset,
            &base,
            noise,
            "pose_noise",
            f64::from(degrees),
        )?);
    }
    for &factor in args.scales.iter().filter(|&&f| f != baseline_factor) {
        let config = RunConfig {
            scale: ImageScale::Factor(factor),
            ..base.clone()
        };
        rows.push(measure(
            &dataset,
            &config,
            Perturbation::None,
            "scale",
            f64::from(factor),
        )?);
    }
    if let Some(params) = &synth_params {
        let first = &dataset.views[0].camera.intrinsics;
        let (width, height) = args.scale.apply(first.width, first.height);
        for (flat, name) in [(false, "textured"), (true, "flat")] {
            let root = regenerate(
                params,
                &args.out.join("data").join(name),
                width,
                height,
                flat,
            )?;
            let copy = open_dataset(&root, glam::Vec3::ZERO)?;
            let config = RunConfig {
                scale: ImageScale::Factor(1),
                ..base.clone()
            };
            let value = if flat { 1.0 } else { 0.0 };
            rows.push(measure(
                &copy,
                &config,
                Perturbation::None,
                "textureless",
                value,
            )?);
        }
    }
    let mask_noise_source = mask_noise_rows(&args.mask_noise_json, &mut rows)?;

    let file = StudyFile {
        dataset: args.dataset.display().to_string(),
        iterations: args.iters,
        scale: args.scale,
        seed: args.seed,
        threads,
        seconds: started.elapsed().as_secs_f64(),
        mask_noise_source,
        rows: &rows,
    };
    let json = serde_json::to_string_pretty(&file)?;
    write_text(&args.out, "stability-study.json", &json)?;
    write_reports(&args.out, &rows)?;
    println!("{}", table(&rows));
    Ok(())
}

/// The synthetic survey parameters in the dataset's `truth/manifest.ron`.
fn synth_params(dataset: &Path) -> anyhow::Result<SynthParams> {
    let manifest_path = dataset.join("truth").join("manifest.ron");
    let text = std::fs::read_to_string(&manifest_path).with_context(|| {
        format!(
            "reading {} (the textureless axis regenerates a synthetic survey; \
             --no-textureless skips it)",
            manifest_path.display()
        )
    })?;
    let manifest: Manifest =
        ron::from_str(&text).with_context(|| format!("reading {}", manifest_path.display()))?;
    Ok(manifest.params)
}

/// Regenerates the survey `params` describe at `width × height`, with flat component colours or
/// not, into `out`; returns the survey folder.
fn regenerate(
    params: &SynthParams,
    out: &Path,
    width: u32,
    height: u32,
    flat: bool,
) -> anyhow::Result<PathBuf> {
    let params = SynthParams {
        out: out.to_path_buf(),
        width,
        height,
        surveys: 1,
        component_colours: flat,
        mask_noise: 0.0,
        ..params.clone()
    };
    eprintln!(
        "generating {} ({width}×{height}, {} colours) …",
        out.display(),
        if flat { "flat component" } else { "textured" }
    );
    damage_twin::synth::generate::generate(&params, &|_, _| {})
        .with_context(|| format!("generating {}", out.display()))?;
    Ok(out.join("survey-1"))
}

/// Appends the mask-noise study's label-mode rows as the mask_noise axis; returns where they
/// came from (None when the file is absent).
fn mask_noise_rows(path: &Path, rows: &mut Vec<StabilityRow>) -> anyhow::Result<Option<String>> {
    let Ok(text) = std::fs::read_to_string(path) else {
        eprintln!("no {}: the mask_noise axis is left out", path.display());
        return Ok(None);
    };
    let file: MaskNoiseFile =
        serde_json::from_str(&text).with_context(|| format!("reading {}", path.display()))?;
    let mut rates: Vec<f64> = file
        .rows
        .iter()
        .filter(|r| r.mode == TrainMode::Label)
        .map(|r| r.rate)
        .collect();
    rates.sort_by(f64::total_cmp);
    rates.dedup();
    for rate in rates {
        let of_rate: Vec<&MaskNoiseRow> = file
            .rows
            .iter()
            .filter(|r| r.mode == TrainMode::Label && r.rate == rate)
            .collect();
        let first = of_rate[0];
        rows.push(StabilityRow {
            axis: "mask_noise".into(),
            value: rate,
            psnr: first.heldout_psnr,
            ssim: None,
            iou: of_rate
                .iter()
                .map(|r| (r.class.clone(), r.twin_iou_heldout))
                .collect(),
            gaussians: first.gaussians,
            seconds: first.train_seconds,
            width: 0,
            height: 0,
        });
    }
    Ok(Some(format!(
        "{} (label mode, {} iterations each)",
        path.display(),
        file.iterations
    )))
}

fn iou(row: &StabilityRow, class: &str) -> String {
    row.iou
        .get(class)
        .map(|v| format!("{v:.3}"))
        .unwrap_or_else(|| "–".into())
}

fn csv(rows: &[StabilityRow]) -> String {
    let mut out = String::from(
        "axis,value,psnr,ssim,iou_crack,iou_spalling,iou_rebar,gaussians,seconds,width,height\n",
    );
    for r in rows {
        out.push_str(&format!(
            "{},{},{:.3},{},{},{},{},{},{:.1},{},{}\n",
            r.axis,
            r.value,
            r.psnr,
            r.ssim.map(|s| format!("{s:.4}")).unwrap_or_default(),
            iou(r, "crack"),
            iou(r, "spalling"),
            iou(r, "rebar"),
            r.gaussians,
            r.seconds,
            r.width,
            r.height
        ));
    }
    out.replace('–', "")
}

fn table(rows: &[StabilityRow]) -> String {
    let mut out = String::from(
        "| axis | value | held-out PSNR | SSIM | IoU crack / spalling / rebar | Gaussians | seconds |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        out.push_str(&format!(
            "| {} | {} | {:.2} dB | {} | {} / {} / {} | {} | {:.0} |\n",
            r.axis,
            r.value,
            r.psnr,
            r.ssim
                .map(|s| format!("{s:.3}"))
                .unwrap_or_else(|| "–".into()),
            iou(r, "crack"),
            iou(r, "spalling"),
            iou(r, "rebar"),
            r.gaussians,
            r.seconds
        ));
    }
    out
}
