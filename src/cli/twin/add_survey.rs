//! `damage-twin twin add-survey DIR --survey NAME --date YYYY-MM-DD --dataset PATH
//! [--align same-frame|joint|colmap] [--photos DIR] [--segment MODEL.onnx]`: a later survey
//! placed in the twin's frame; `joint` reports the registration's residual. With `--photos` and
//! `--align colmap` the survey arrives as photos: COLMAP registers them into the latest posed
//! survey's model (old poses held) and writes the dataset PATH first
//! (`timeline::register_survey`); the residual is printed and kept. With `--segment` the survey may arrive as photos
//! alone: its photos are segmented first and the masks written into its dataset
//! (`timeline::segment_survey`), then it is added.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};

use damage_twin::segment::SegmentModel;
use damage_twin::timeline::Twin;
use damage_twin::timeline::segment_survey::NewSurvey;
use damage_twin::timeline::survey::AlignMode;

use crate::cli::args::{JobArgs, LockArgs, parse_survey_name};
use crate::cli::pose::{colmap_bar, show};
use crate::cli::segment::{ModelArgs, print_summary};
use damage_twin::scene::sfm::PoseOptions;

#[derive(clap::Args, Debug)]
pub struct Args {
    pub dir: PathBuf,
    /// The survey's name, also its folder's: ASCII letters, digits, `-`, `_`, `.`.
    #[arg(long, value_parser = parse_survey_name)]
    pub survey: String,
    /// The survey's date, YYYY-MM-DD (not before the latest survey's).
    #[arg(long)]
    pub date: String,
    #[arg(long)]
    pub dataset: PathBuf,
    /// same-frame: the poses are in the twin's frame; joint: a COLMAP model of the latest
    /// survey's images and the new ones, registered through the images they share; colmap: the
    /// photos of --photos registered by COLMAP into the latest survey `pose` made (old poses
    /// held), written as --dataset.
    #[arg(long, default_value = "same-frame")]
    pub align: AlignMode,
    /// The survey's photos (with --align colmap): --dataset is then the folder to write.
    #[arg(long)]
    pub photos: Option<PathBuf>,
    /// Segment the survey's photos with this ONNX model first (masks written into the dataset,
    /// never over masks already there); the model options are `segment`'s.
    #[arg(long)]
    pub segment: Option<PathBuf>,
    #[command(flatten)]
    pub model: ModelArgs,
    #[command(flatten)]
    pub job: JobArgs,
    #[command(flatten)]
    pub lock: LockArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut twin = super::open_to_write(&args.dir, &args.lock, "twin add-survey")?;
    if let Some(photos) = &args.photos {
        register_photos(&twin, &args, photos)?;
    }
    if let Some(model) = &args.segment {
        segment_survey(&twin, &args, model)?;
    }
    // Added to the project as it is when the lock is held: another survey added meanwhile stays.
    let registration = twin.commit(|twin| {
        twin.add_placed_survey(&args.survey, &args.date, &args.dataset, args.align)
    })?;
    match registration {
        Some(r) => println!(
            "added survey {} ({} views), registered through {} shared images ({} kept): residual \
             {:.4} units RMS ({:.3} % of the cameras' spread), scale {:.4}",
            args.survey,
            twin.survey(&args.survey)?
                .views
                .as_ref()
                .map_or(0, Vec::len),
            r.shared,
            r.inliers,
            r.residual,
            100.0 * r.relative_residual,
            r.similarity.scale
        ),
        None if args.align == AlignMode::Colmap => match twin.load_registration(&args.survey)? {
            Some(record) => println!("added survey {}: {}", args.survey, record.describe()),
            None => println!("added survey {} (registered by COLMAP)", args.survey),
        },
        None => println!("added survey {} (same frame)", args.survey),
    }
    Ok(())
}

/// The photos registered by COLMAP into the twin's posed survey, written as `--dataset`.
fn register_photos(twin: &Twin, args: &Args, photos: &std::path::Path) -> anyhow::Result<()> {
    if args.align != AlignMode::Colmap {
        anyhow::bail!(
            "--photos registers the photos by COLMAP: give --align colmap (the other alignments \
             take a posed --dataset)"
        );
    }
    let (reference, _) = twin.colmap_reference()?;
    let options = PoseOptions {
        threads: args.job.threads.unwrap_or(PoseOptions::default().threads),
        ..PoseOptions::default()
    };
    let bar = colmap_bar(args.job.quiet)?;
    let summary = twin.register_survey_photos(photos, &args.dataset, &options, &|p| show(&bar, p));
    bar.finish_and_clear();
    let summary = summary?;
    println!(
        "registered {} of {} photos into survey {reference}'s model in {:.0} s ({}); dataset: {}",
        summary.registered.len(),
        summary.photos,
        summary.seconds,
        summary.engine,
        args.dataset.display()
    );
    for warning in &summary.warnings {
        eprintln!("warning: {warning}");
    }
    Ok(())
}

/// The survey's photos through `model_path` into its dataset's masks, with a progress bar.
fn segment_survey(twin: &Twin, args: &Args, model_path: &std::path::Path) -> anyhow::Result<()> {
    let settings = args
        .model
        .settings(false, twin.project.settings.background)?;
    let model = SegmentModel::open(model_path, settings.classes.len())?;
    let bar = if args.job.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(0)
    };
    bar.set_style(
        ProgressStyle::with_template("{msg:>10} {bar:30} {pos}/{len} photos ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message("segment");
    bar.enable_steady_tick(Duration::from_millis(250));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.job.threads.unwrap_or(0))
        .build()
        .context("the worker threads")?;
    let summary = pool.install(|| {
        twin.segment_new_survey(
            NewSurvey {
                name: &args.survey,
                date: &args.date,
                dataset: &args.dataset,
                align: args.align,
            },
            &model,
            &settings,
            &mut |done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
                true
            },
        )
    });
    bar.finish_and_clear();
    let summary = summary.with_context(|| format!("segmenting survey {}", args.survey))?;
    print_summary(&summary, pool.current_num_threads(), &args.dataset);
    Ok(())
}
