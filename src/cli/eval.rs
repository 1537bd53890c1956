//! `damage-twin eval MODEL.ply DATASET`: PSNR and SSIM of a trained model on the held-out views
//! (the same rule as `train`) and its rendered damage against the reference masks, as text or
//! `--json`. The evaluation is `damage::assess`.

use std::path::PathBuf;
use std::sync::Arc;

use serde::Serialize;

use damage_twin::damage::TrainMode;
use damage_twin::damage::assess::{EvalRequest, ViewScore, evaluate_job};
use damage_twin::damage::evaluate::{DamageFigures, DamageReadout, OverlaySource};
use damage_twin::damage::view_damage::ViewDamage;
use damage_twin::train::job::JobOptions;
use damage_twin::train::views::split_views;

use super::args::{HoldoutArgs, ImageArgs, drive, open_dataset, palette, read_model};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Trained model (3DGS PLY).
    pub model: PathBuf,
    /// The dataset it was trained on.
    pub dataset: PathBuf,
    #[command(flatten)]
    pub images: ImageArgs,
    #[command(flatten)]
    pub holdout: HoldoutArgs,
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
    /// Each held-out view's damage alone, with the ground sample distance at its damage.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    damage_views: Vec<ViewDamage>,
    /// `--half-appearance`: mean held-out PSNR of the right halves, light fitted on the left.
    #[serde(skip_serializing_if = "Option::is_none")]
    psnr_half_appearance: Option<f64>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let splats = Arc::new(read_model(&args.model)?);
    let dataset = Arc::new(open_dataset(&args.dataset, args.images.background)?);
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
        scale: args.images.scale,
        background: args.images.background,
        sh_degree: splats.sh_degree,
        photometric: true,
        half_appearance: args.half_appearance,
        readout,
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
        damage_views: scores.damage_views,
        psnr_half_appearance: scores.psnr_half_appearance,
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
        print_damage_views(&report.damage_views);
    }
    Ok(())
}

/// One line per view: its ground sample distance at the damage and its own IoU per class (a thin
/// crack's IoU falls as each pixel spans more of the wall, so views far from the wall score
/// lower for the same model).
fn print_damage_views(views: &[ViewDamage]) {
    if views.len() < 2 {
        return;
    }
    println!("  per view (IoU; ground sample distance at the view's damage):");
    for v in views {
        let gsd = v
            .ground_sample_mm
            .map_or_else(|| "   -   ".to_string(), |mm| format!("{mm:5.1} mm"));
        let ious: Vec<String> = v
            .figures
            .iou
            .iter()
            .map(|(class, iou)| format!("{class} {iou:.3}"))
            .collect();
        println!("    {:<20} {gsd}/px  {}", v.name, ious.join("  "));
    }
}
