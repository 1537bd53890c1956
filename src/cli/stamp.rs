//! `damage-twin stamp`: damage with exact truth drawn onto a real posed capture (docs/STAMP.md).
//! Argument parsing and reporting only; the work is `synth::stamp::stamp`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use damage_twin::synth::stamp::{self, StampParams, parse_classes};
use indicatif::{ProgressBar, ProgressStyle};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The posed capture: a COLMAP folder (images/ + sparse/0 with points3D) or transforms.json.
    pub capture: PathBuf,
    /// Output folder (survey-1/ and survey-2/ are written in it).
    #[arg(long)]
    pub out: PathBuf,
    /// Folders of real crack photos with masks (crackforest: image/ + masks/; or N.png + N_m.png).
    #[arg(long = "crack-photos", required = true, num_args = 1..)]
    pub crack_photos: Vec<PathBuf>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Metres per model unit (default: the capture's georef.json, else its photos' EXIF GPS).
    #[arg(long)]
    pub metres_per_unit: Option<f64>,
    /// Classes to stamp, comma-separated (crack, spalling, rebar; rebar needs spalling).
    #[arg(long, default_value = "crack,spalling,rebar")]
    pub classes: String,
    /// Survey-1 cracks and spalls, and those added in survey 2.
    #[arg(long, default_value_t = 6)]
    pub cracks: usize,
    #[arg(long, default_value_t = 3)]
    pub spalls: usize,
    #[arg(long, default_value_t = 2)]
    pub new_cracks: usize,
    #[arg(long, default_value_t = 1)]
    pub new_spalls: usize,
    /// Nominal crack length in metres (each crack draws 0.6–1.0 of it).
    #[arg(long, default_value_t = 1.5)]
    pub crack_length_m: f64,
    /// Nominal spall diameter in metres (each draws 0.7–1.0 of it).
    #[arg(long, default_value_t = 0.6)]
    pub spall_diameter_m: f64,
    /// Cracks are widened to at least this mean width in metres (real crack masks are a few
    /// millimetres wide at their photos' scale, under a pixel at street distance).
    #[arg(long, default_value_t = 0.02)]
    pub crack_width_m: f64,
    /// Sparse points within this distance of a plane are its inliers (metres).
    #[arg(long, default_value_t = 0.1)]
    pub plane_tolerance_m: f64,
    /// A surface is stamped when at least this many photos see it.
    #[arg(long, default_value_t = 3)]
    pub min_views: usize,
    /// Number of surveys (1 or 2).
    #[arg(long, default_value_t = 2)]
    pub surveys: u32,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let params = StampParams {
        seed: args.seed,
        metres_per_unit: args.metres_per_unit,
        classes: parse_classes(&args.classes).map_err(|e| anyhow::anyhow!("--classes: {e}"))?,
        cracks: args.cracks,
        spalls: args.spalls,
        new_cracks: args.new_cracks,
        new_spalls: args.new_spalls,
        crack_length_m: args.crack_length_m,
        spall_diameter_m: args.spall_diameter_m,
        crack_width_m: args.crack_width_m,
        plane_tolerance_m: args.plane_tolerance_m,
        min_views: args.min_views,
        surveys: args.surveys,
        ..StampParams::new(&args.capture, &args.out, args.crack_photos.clone())
    };
    let start = Instant::now();
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("stamping [{bar:40}] {pos}/{len} photos, {elapsed}")
            .context("progress bar template")?
            .progress_chars("=> "),
    );
    let summary = stamp::stamp(&params, &|done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })
    .with_context(|| format!("stamping damage onto {}", args.capture.display()))?;
    bar.finish_and_clear();
    println!(
        "{} photos; {:.4} metres per unit (from {}); {} planes, {} seen by {}+ photos{}",
        summary.views,
        summary.scale.metres_per_unit,
        summary.scale.source,
        summary.planes,
        summary.usable_planes,
        params.min_views,
        if summary.not_placed > 0 {
            format!("; {} decals found no spot", summary.not_placed)
        } else {
            String::new()
        }
    );
    for (k, (decals, pixels)) in summary
        .decals
        .iter()
        .zip(&summary.damage_pixels)
        .enumerate()
    {
        let shown: Vec<String> = pixels.iter().map(|(c, n)| format!("{c} {n}")).collect();
        println!(
            "survey-{}: {} decals; damage pixels over all photos: {}",
            k + 1,
            decals,
            shown.join(", ")
        );
    }
    println!("done in {:.1} s", start.elapsed().as_secs_f64());
    Ok(())
}
