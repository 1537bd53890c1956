//! The headless client: parses arguments and drives the library's job API. No algorithms here.
//! Every subcommand lives in its own file with an `Args` struct and a `run` function.

mod args;
mod bench;
mod bench_refine;
mod bench_render;
mod cluster;
mod compact;
mod demo;
mod eval;
mod export;
mod inspect;
mod launch;
mod masks;
mod merge;
mod partition;
mod pose;
mod refine;
mod render;
mod report;
mod segment;
mod stamp;
mod study;
mod synth;
mod train;
mod train_block;
mod twin;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "damage-twin",
    version,
    about = "A 3D digital twin of structural damage"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Show what a dataset folder holds (format, cameras, images, points, masks, problems).
    Inspect(inspect::Args),
    /// Generate the procedural damaged building and its two drone surveys (the demo data).
    Synth(synth::Args),
    /// Damage with exact truth drawn onto a real posed capture's photos (two surveys).
    Stamp(stamp::Args),
    /// Pose a folder of photos with COLMAP and write a dataset (metres and north from EXIF GPS).
    Pose(pose::Args),
    /// Train a splat model from a dataset (CPU engine); writes model.ply, metrics.json, curve.csv.
    Train(train::Args),
    /// PSNR and SSIM of a model on a dataset's held-out views.
    Eval(eval::Args),
    /// Hierarchical refinement: select a twin's damage Gaussians, draw hull masks, refine them at
    /// high resolution with the rest frozen.
    Refine(refine::Args),
    /// Prune a model to its most important Gaussians and fine-tune it briefly (JSON report).
    Compact(compact::Args),
    /// Damage masks from COCO JSON, LabelMe JSON or class PNGs into a dataset (import), and a
    /// twin's rendered masks out as COCO JSON (export).
    #[command(subcommand)]
    Masks(masks::Masks),
    /// Render one view of a model to a PNG.
    Render(render::Args),
    /// Write a model for other viewers as SPZ (compressed) or PLY, with its bytes per Gaussian.
    Export(export::Args),
    /// The inspection report of a twin project: damage regions measured per survey (lengths,
    /// widths, areas, growth, new regions) as report.html and report.json.
    Report(report::Args),
    /// Time per training iteration by stage, memory and bytes per Gaussian (JSON).
    Bench(bench::Args),
    /// Milliseconds per frame by stage, GPU (wgpu) and CPU side by side (JSON).
    BenchRender(bench_render::Args),
    /// Damage masks from the photos: an ONNX segmentation model over a dataset's photos, in
    /// tiles; writes masks/<class>/ and probabilities/<class>/ beside them.
    Segment(segment::Args),
    /// Studies that measure the twin (mask-noise: how much segmentation error it removes).
    #[command(subcommand)]
    Study(study::Study),
    /// The survey timeline of a twin project: new, add-survey, detect, update, status.
    #[command(subcommand)]
    Twin(twin::Twin),
    /// Cut a posed dataset into blocks along its long axis: a plan folder (plan.json, block
    /// manifests, blocks.png) for training block by block (docs/CLUSTER.md).
    Partition(partition::Args),
    /// Train one block of a plan (K from --block or the engine's environment) into the plan
    /// folder; a finished block is a no-op.
    TrainBlock(train_block::Args),
    /// Run a plan's blocks through an engine: Slurm or Kubernetes job files, or local processes.
    #[command(subcommand)]
    Cluster(cluster::Cluster),
    /// One model from a plan's trained blocks, with the seam report on held-out views.
    Merge(merge::Args),
    /// The built-in demo building: the app, or with --headless synth + train + eval + charts.
    Demo(demo::Args),
    /// The app on a dataset, a twin project or a PLY model.
    Open(launch::OpenArgs),
}

pub fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(warning) = damage_twin::simd::environment_warning() {
        eprintln!("warning: {warning}");
    }
    let result = match cli.command {
        // No subcommand: the desktop app on the built-in demo building.
        None => launch::demo_window(),
        Some(Command::Inspect(args)) => inspect::run(args),
        Some(Command::Synth(args)) => synth::run(args),
        Some(Command::Stamp(args)) => stamp::run(args),
        Some(Command::Pose(args)) => pose::run(args),
        Some(Command::Train(args)) => train::run(args),
        Some(Command::Eval(args)) => eval::run(args),
        Some(Command::Refine(args)) => refine::run(args),
        Some(Command::Compact(args)) => compact::run(args),
        Some(Command::Masks(command)) => masks::run(command),
        Some(Command::Render(args)) => render::run(args),
        Some(Command::Export(args)) => export::run(args),
        Some(Command::Report(args)) => report::run(args),
        Some(Command::Bench(args)) => bench::run(args),
        Some(Command::BenchRender(args)) => bench_render::run(args),
        Some(Command::Segment(args)) => segment::run(args),
        Some(Command::Study(study)) => study::run(study),
        Some(Command::Twin(command)) => twin::run(command),
        Some(Command::Partition(args)) => partition::run(args),
        Some(Command::TrainBlock(args)) => train_block::run(args),
        Some(Command::Cluster(command)) => cluster::run(command),
        Some(Command::Merge(args)) => merge::run(args),
        Some(Command::Demo(args)) => demo::run(args),
        Some(Command::Open(args)) => launch::open_window(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line, the whole cause chain: "reading sparse/0/cameras.bin: truncated ...".
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
