//! `damage-twin eval MODEL.ply DATASET`: PSNR and SSIM of a trained model on the held-out views
//! (the same rule as `train`) and its rendered damage against the reference masks, as text or
//! `--json`. The evaluation is `damage::assess`.

use std::path::PathBuf;
use std::sync::Arc;

use glam::Vec3;
use serde::Serialize;

use damage_twin::damage::TrainMode;
use damage_twin::damage::assess::{EvalRequest, ViewScore, evaluate_job};
use damage_twin::damage::evaluate::{DamageFigures, DamageReadout, OverlaySource};
use damage_twin::scene::ImageScale;
use damage_twin::train::job::JobOptions;
use damage_twin::train::views::split_views;

use super::args::{
    HoldoutArgs, drive, open_dataset, palette, parse_background, parse_scale, read_model,
};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Trained model (3DGS PLY).
    pub model: PathBuf,
    /// The dataset it was trained on.
    pub dataset: PathBuf,
    #[arg(long, default_value = "1", value_parser = parse_scale)]
    pub scale: ImageScale,
    #[command(flatten)]
    pub holdout: HoldoutArgs,
    #[arg(long, default_value = "black", value_parser = parse_background)]
    pub background: Vec3,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// How rendered damage is read: label (label channels at 0.5) or overlay (class colours);
    /// default: label when the model has label channels, else overlay.
    #[arg(long)]
    pub mode: Option<TrainMode>,
    /// Class colour override for overlay mode, class=r,g,b (repeatable), for a model that does
    /// not carry its colours (older files); a model's own colours win.
    #[arg(long = "colour")]
    pub colours: Vec<String>,
    /// Overlay mode: colour distance (8-bit RGB) within which a colour is a class colour
    /// (default: the model's saved tolerance, else 40).
    #[arg(long)]
    pub tolerance: Option<f32>,
    /// Overlay mode: read the class colours from the Gaussians' base colours (gaussians) or
    /// from the rendered pixels (pixels, as the published method does).
    #[arg(long, default_value = "gaussians")]
    pub overlay_readout: OverlaySource,
    /// Also score each held-out photo's right half after fitting its light (a gain and offset
    /// per channel) to the render on its left half: the NeRF-W protocol for a model whose
    /// training photos differ in exposure.
    #[arg(long)]
    pub half_appearance: bool,
}

#[derive(Serialize)]
struct Report {
    psnr: f64,
    ssim: f64,
    views: Vec<ViewScore>,
    gaussians: usize,
    /// How damage was read (absent without masks).
    damage_mode: Option<TrainMode>,
    damage_reference: Option<String>,
    /// Per-class `iou`, `precision`, `recall`, `f1` on the held-out views.
    #[serde(flatten)]
    damage: Option<DamageFigures>,
    /// `--half-appearance`: mean held-out PSNR of the right halves, light fitted on the left.
    #[serde(skip_serializing_if = "Option::is_none")]
    psnr_half_appearance: Option<f64>,
}

/// The NeRF-W protocol: per held-out view, the light fitted on the left half of the photo (gain
/// and offset per channel, `timeline::appearance::fit_transform`) is applied to the render, and
/// PSNR is taken over the right half (used pixels only). The mean over views.
fn half_appearance_psnr(
    splats: &damage_twin::splats::Splats,
    dataset: &damage_twin::scene::Dataset,
    indices: &[usize],
    scale: ImageScale,
    background: Vec3,
) -> anyhow::Result<f64> {
    use damage_twin::raster::{RenderSettings, render};
    let settings = RenderSettings::new(background, splats.sh_degree);
    let mut total = 0.0;
    for &index in indices {
        let view = dataset.load_view(index, scale)?;
        let out = render(splats, &view.camera, &settings);
        let w = view.image.width as usize;
        let used = |p: usize| view.ignore.as_ref().is_none_or(|m| m.data[p] != 0);
        let light =
            damage_twin::timeline::appearance::fit_transform(&out.color, &view.image.data, &|p| {
                p % w < w / 2 && used(p)
            });
        let mut lit = damage_twin::scene::RgbImage {
            width: out.width,
            height: out.height,
            data: out.color,
        };
        light.apply(&mut lit);
        let right: Vec<u8> = (0..w * view.image.height as usize)
            .map(|p| u8::from(p % w >= w / 2 && used(p)))
            .collect();
        total += damage_twin::metrics::psnr_masked(&lit.data, &view.image.data, &right);
    }
    Ok(total / indices.len().max(1) as f64)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let splats = Arc::new(read_model(&args.model)?);
    let dataset = Arc::new(open_dataset(&args.dataset, args.background)?);
    let (_, test_idx) =
        split_views(&dataset, &args.holdout.holdout()).map_err(anyhow::Error::msg)?;
    let mut readout = DamageReadout::for_model(&splats, palette(&args.colours)?);
    if let Some(tolerance) = args.tolerance {
        readout.tolerance = tolerance;
    }
    readout.overlay_source = args.overlay_readout;
    if let Some(mode) = args.mode {
        readout.mode = mode;
    }
    let request = EvalRequest {
        indices: test_idx,
        scale: args.scale,
        background: args.background,
        sh_degree: splats.sh_degree,
        photometric: true,
        readout,
    };
    let half = if args.half_appearance {
        Some(half_appearance_psnr(
            &splats,
            &dataset,
            &request.indices,
            args.scale,
            args.background,
        )?)
    } else {
        None
    };
    let job = evaluate_job(dataset, splats.clone(), request, JobOptions::headless(None));
    let scores = drive(job, "evaluation", args.json, |_| {})?;
    let report = Report {
        psnr: scores.psnr.unwrap_or(f64::NAN),
        ssim: scores.ssim.unwrap_or(f64::NAN),
        views: scores.views,
        gaussians: splats.len(),
        damage_mode: scores.damage.as_ref().map(|_| readout.mode),
        damage_reference: scores.damage_reference,
        damage: scores.damage,
        psnr_half_appearance: half,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    for v in &report.views {
        println!("{:<24} PSNR {:6.2} dB  SSIM {:.4}", v.name, v.psnr, v.ssim);
    }
    println!(
        "held-out mean over {} views: PSNR {:.2} dB, SSIM {:.4} ({} Gaussians)",
        report.views.len(),
        report.psnr,
        report.ssim,
        report.gaussians
    );
    if let Some(half) = report.psnr_half_appearance {
        println!("right halves, light fitted on the left halves: PSNR {half:.2} dB");
    }
    if let (Some(d), Some(mode)) = (&report.damage, report.damage_mode) {
        println!(
            "damage ({mode} mode, against {}):",
            report.damage_reference.as_deref().unwrap_or("-")
        );
        for (class, iou) in &d.iou {
            println!(
                "  {class:<10} IoU {iou:.3}  precision {:.3}  recall {:.3}  F1 {:.3}  ({} reference pixels)",
                d.precision[class], d.recall[class], d.f1[class], d.reference_pixels[class]
            );
        }
    }
    Ok(())
}
