//! The stability suite (issue 24 §3): where the twin holds and where it breaks. Each axis moves
//! alone from a baseline label-mode run: fewer training views, noisy training poses, the
//! training scale, a textureless building (the dataset regenerated with flat component colours at
//! the training size, beside a textured copy made the same way), and mask noise (the mask-noise
//! study's saved label-mode rows).

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::damage::TrainMode;
use crate::damage::setup::RunConfig;
use crate::scene::files::read_text;
use crate::scene::limits::MAX_PROJECT_JSON_BYTES;
use crate::scene::open::OpenOptions;
use crate::scene::{Dataset, ImageScale};
use crate::studies::stability::mask_noise_axis::mask_noise_rows;
use crate::studies::stability::perturb::Perturbation;
use crate::studies::stability::row::StabilityRow;
use crate::studies::stability::run::stability_run;
use crate::synth::params::SynthParams;
use crate::train::views::{Holdout, split_views};

/// The suite's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct StabilityConfig {
    /// Steps of every run.
    pub iterations: u32,
    /// The baseline's training scale (a factor: the scale axis moves it).
    pub scale: ImageScale,
    pub seed: u64,
    pub threads: usize,
    /// Training-view counts (the baseline trains on all of them).
    pub views: Vec<usize>,
    /// Pose noise of the training cameras, degrees.
    pub pose_noise: Vec<f32>,
    /// Training downscale factors besides the baseline's.
    pub scales: Vec<u32>,
    /// Run the textureless axis (it regenerates the dataset twice at the training size).
    pub textureless: bool,
    /// Where the textureless axis writes its regenerated surveys (`textured/`, `flat/`).
    pub work_dir: PathBuf,
    /// The mask-noise study whose label-mode rows make the mask_noise axis.
    pub mask_noise_json: PathBuf,
}

/// What the suite measured.
#[derive(Clone, Debug)]
pub struct StabilityOutcome {
    pub rows: Vec<StabilityRow>,
    /// Where the mask_noise rows come from (None when that study's file is absent).
    pub mask_noise_source: Option<String>,
}

/// The parts of `truth/manifest.ron` this study reads.
#[derive(Deserialize)]
struct Manifest {
    params: SynthParams,
}

/// Runs every axis on `dataset` (a synthetic survey of the demo building when the textureless
/// axis runs); `log` hears each run as it starts and ends.
pub fn run_stability(
    dataset: &Dataset,
    config: &StabilityConfig,
    log: &mut dyn FnMut(String),
) -> Result<StabilityOutcome, String> {
    // Read before any training, so a dataset that cannot be regenerated fails now.
    let synth_params = if config.textureless {
        Some(synth_params(&dataset.root)?)
    } else {
        None
    };
    let base = RunConfig {
        mode: TrainMode::Label,
        scale: config.scale,
        iterations: config.iterations,
        holdout: Holdout::Auto { every: 8 },
        seed: config.seed,
        eval_every: 0,
        ..RunConfig::default()
    };
    let baseline_factor = match config.scale {
        ImageScale::Factor(f) => f,
        _ => return Err("--scale must be a factor (1, 2, 4, 8) for the scale axis".into()),
    };
    let mut rows: Vec<StabilityRow> = Vec::new();
    let threads = config.threads;
    let measure = |dataset: &Dataset,
                   run: &RunConfig,
                   perturbation: Perturbation,
                   axis: &str,
                   value: f64,
                   log: &mut dyn FnMut(String)| {
        measure_one(dataset, run, perturbation, (axis, value), threads, log)
    };

    // The baseline stands in each axis at its own setting.
    let baseline = measure(dataset, &base, Perturbation::None, "baseline", 0.0, log)?;
    let training_views = split_views(dataset, &base.holdout)?.0.len();
    let at = |axis: &str, value: f64| StabilityRow {
        axis: axis.to_string(),
        value,
        ..baseline.clone()
    };
    rows.push(at("views", training_views as f64));
    rows.push(at("pose_noise", 0.0));
    rows.push(at("scale", f64::from(baseline_factor)));
    for &n in config.views.iter().filter(|&&n| n < training_views) {
        rows.push(measure(
            dataset,
            &base,
            Perturbation::Views(n),
            "views",
            n as f64,
            log,
        )?);
    }
    for &degrees in &config.pose_noise {
        let noise = Perturbation::PoseNoise {
            degrees,
            seed: config.seed ^ 0x9053,
        };
        rows.push(measure(
            dataset,
            &base,
            noise,
            "pose_noise",
            f64::from(degrees),
            log,
        )?);
    }
    for &factor in config.scales.iter().filter(|&&f| f != baseline_factor) {
        let run = RunConfig {
            scale: ImageScale::Factor(factor),
            ..base.clone()
        };
        rows.push(measure(
            dataset,
            &run,
            Perturbation::None,
            "scale",
            f64::from(factor),
            log,
        )?);
    }
    if let Some(params) = &synth_params {
        let first = &dataset.views[0].camera.intrinsics;
        let (width, height) = config.scale.apply(first.width, first.height);
        for (flat, name) in [(false, "textured"), (true, "flat")] {
            let out = config.work_dir.join(name);
            log(format!(
                "generating {} ({width}×{height}, {} colours) …",
                out.display(),
                if flat { "flat component" } else { "textured" }
            ));
            let root = regenerate(params, &out, width, height, flat)?;
            let copy = open_copy(&root, log)?;
            let run = RunConfig {
                scale: ImageScale::Factor(1),
                ..base.clone()
            };
            let value = if flat { 1.0 } else { 0.0 };
            rows.push(measure(
                &copy,
                &run,
                Perturbation::None,
                "textureless",
                value,
                log,
            )?);
        }
    }
    let mask_noise_source = mask_noise_rows(&config.mask_noise_json, &mut rows, log)?;
    Ok(StabilityOutcome {
        rows,
        mask_noise_source,
    })
}

/// One run of the suite, announced to `log` and summed up there.
fn measure_one(
    dataset: &Dataset,
    run: &RunConfig,
    perturbation: Perturbation,
    (axis, value): (&str, f64),
    threads: usize,
    log: &mut dyn FnMut(String),
) -> Result<StabilityRow, String> {
    log(format!("{axis} = {value} …"));
    let row = stability_run(dataset, run, perturbation, axis, value, Some(threads))?;
    log(format!(
        "  PSNR {:.2} dB, IoU {:?}, {} Gaussians, {:.0} s",
        row.psnr, row.iou, row.gaussians, row.seconds
    ));
    Ok(row)
}

/// The synthetic survey parameters in the dataset's `truth/manifest.ron`.
fn synth_params(dataset: &Path) -> Result<SynthParams, String> {
    let manifest_path = dataset.join("truth").join("manifest.ron");
    let text = read_text(&manifest_path, MAX_PROJECT_JSON_BYTES).map_err(|e| {
        format!(
            "reading {} (the textureless axis regenerates a synthetic survey; \
             --no-textureless skips it): {e}",
            manifest_path.display()
        )
    })?;
    let manifest: Manifest =
        ron::from_str(&text).map_err(|e| format!("reading {}: {e}", manifest_path.display()))?;
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
) -> Result<PathBuf, String> {
    let params = SynthParams {
        out: out.to_path_buf(),
        width,
        height,
        surveys: 1,
        component_colours: flat,
        mask_noise: 0.0,
        ..params.clone()
    };
    crate::synth::generate::generate(&params, &|_, _| {})
        .map_err(|e| format!("generating {}: {e}", out.display()))?;
    Ok(out.join("survey-1"))
}

/// Opens a regenerated survey on black, its warnings to `log`.
fn open_copy(root: &Path, log: &mut dyn FnMut(String)) -> Result<Dataset, String> {
    let dataset = Dataset::open(root, &OpenOptions::default())
        .map_err(|e| format!("opening dataset {}: {e}", root.display()))?;
    if dataset.views.is_empty() {
        return Err(format!("{} has no usable views", root.display()));
    }
    for warning in &dataset.warnings {
        log(format!("warning: {warning}"));
    }
    Ok(dataset)
}
