//! `damage-twin pose PHOTOS --out DATASET`: COLMAP poses a folder of photos and the result is
//! written as a dataset (`scene::sfm`), with a progress bar from COLMAP's own output. Parsing and
//! printing only.

use std::path::PathBuf;

use anyhow::Context;
use damage_twin::scene::sfm::{self, Engine, Matching, PoseOptions, Progress, Stage};
use indicatif::{ProgressBar, ProgressStyle};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Folder of photos (JPEG or PNG, not its sub-folders); masks in PHOTOS/masks/ or beside a
    /// folder named images/ come along.
    pub photos: PathBuf,
    /// The dataset folder to write (must not exist yet, or be empty).
    #[arg(long)]
    pub out: PathBuf,
    /// Which image pairs COLMAP matches: exhaustive (every pair), sequential (file-name order:
    /// strips, walks) or spatial (EXIF GPS neighbours). Default: exhaustive up to 20 photos,
    /// then sequential.
    #[arg(long, value_parser = parse_matching)]
    pub matching: Option<Matching>,
    /// SIFT features per photo.
    #[arg(long, default_value_t = PoseOptions::default().max_features)]
    pub max_features: usize,
    /// Photos each photo is matched with in sequential matching.
    #[arg(long, default_value_t = PoseOptions::default().sequential_overlap)]
    pub overlap: usize,
    /// Surveyed control points (CSV, docs/POSE.md): their fit gives the metres and frame
    /// instead of GPS; points marked `check` are held out and their error reported.
    #[arg(long)]
    pub control_points: Option<PathBuf>,
    /// CPU threads COLMAP may use (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    #[command(flatten)]
    pub engine: EngineArg,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// `--engine`, shared by `pose` and `twin add-survey --photos`.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct EngineArg {
    /// The SfM engine: pycolmap (COLMAP 4 through `pip install pycolmap`, run by the shipped
    /// script) or colmap (the `colmap` program, Debian's 3.8). Default: `colmap` when
    /// DAMAGE_TWIN_COLMAP names a program; for `add-survey --photos` the engine that posed the
    /// survey registered into; else the one measured best on lund (docs/POSE.md): pycolmap.
    #[arg(long, value_parser = parse_engine)]
    pub engine: Option<Engine>,
}

fn parse_engine(text: &str) -> Result<Engine, String> {
    Engine::parse(text).ok_or_else(|| format!("{text:?}: expected pycolmap or colmap"))
}

fn parse_matching(text: &str) -> Result<Matching, String> {
    match text {
        "exhaustive" => Ok(Matching::Exhaustive),
        "sequential" => Ok(Matching::Sequential),
        "spatial" => Ok(Matching::Spatial),
        other => Err(format!(
            "{other:?}: expected exhaustive, sequential or spatial"
        )),
    }
}

/// A progress bar for a COLMAP run (hidden when `quiet`), moved by `show`.
pub fn colmap_bar(quiet: bool) -> anyhow::Result<ProgressBar> {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(0)
    };
    bar.set_style(
        ProgressStyle::with_template("{msg:>9} [{bar:40}] {pos}/{len} {elapsed}")
            .context("progress bar template")?
            .progress_chars("=> "),
    );
    Ok(bar)
}

/// COLMAP's progress `p` on `bar`.
pub fn show(bar: &ProgressBar, p: Progress) {
    if bar.message() != p.stage.label() {
        bar.set_message(p.stage.label());
    }
    bar.set_length(p.total as u64);
    bar.set_position(p.done as u64);
    if p.stage == Stage::Write {
        bar.set_position(0);
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let options = PoseOptions {
        matching: args.matching,
        threads: args.threads.unwrap_or(PoseOptions::default().threads),
        max_features: args.max_features,
        sequential_overlap: args.overlap,
        control_points: args.control_points.clone(),
        engine: args.engine.engine,
        ..PoseOptions::default()
    };
    let bar = colmap_bar(args.quiet)?;
    let summary = sfm::pose_photos(&args.photos, &args.out, &options, &|p| show(&bar, p));
    bar.finish_and_clear();
    let summary = summary?;
    println!(
        "posed {} of {} photos ({} matching, {}) in {:.0} s: {} points, mean reprojection error \
         {:.2} px",
        summary.registered.len(),
        summary.photos,
        summary.matching.name(),
        summary.engine,
        summary.seconds,
        summary.points,
        summary.mean_reprojection_error_px
    );
    if summary.components.len() > 1 {
        println!(
            "COLMAP made {} components ({:?} photos): the largest is the dataset",
            summary.components.len(),
            summary.components
        );
    }
    if !summary.unregistered.is_empty() {
        println!(
            "not registered (left out of the dataset): {}",
            summary.unregistered.join(", ")
        );
    }
    if let Some(fit) = &summary.control_points {
        for p in &fit.points {
            println!(
                "control point {}{}: residual {:.3} m",
                p.name,
                if p.check { " (check)" } else { "" },
                p.residual_m
            );
        }
        if let Some(rms) = fit.check_rms_m {
            println!("check points: {rms:.3} m RMS");
        }
    }
    match (&summary.georeference, &summary.georeference_note) {
        (Some(g), _) => println!(
            "georeferenced from {:?}: {:.4} m per unit, residual {:.2} m RMS over {} positions \
             ({} rejected), baseline {:.1} m, scale good to ±{:.1} %{}",
            g.source,
            g.metres_per_unit(),
            g.rms_m,
            g.used.len(),
            g.rejected.len(),
            g.baseline_m,
            100.0 * g.scale_uncertainty,
            if g.source == sfm::GeorefSource::Gps && summary.gps_plausible == Some(false) {
                " (too large for a right model: see the warning)"
            } else {
                ""
            }
        ),
        (None, Some(note)) => println!("no georeference: {note}"),
        (None, None) => {}
    }
    for warning in &summary.warnings {
        eprintln!("warning: {warning}");
    }
    println!(
        "dataset: {} (COLMAP's log: {})",
        args.out.display(),
        args.out.join(sfm::pose::LOG_FILE).display()
    );
    Ok(())
}
