//! `damage-twin twin add-survey DIR --survey NAME --date YYYY-MM-DD --dataset PATH
//! [--align same-frame|joint|colmap] [--photos DIR] [--segment MODEL.onnx]`: a later survey
//! placed in the twin's frame; `joint` reports the registration's residual. With `--photos` and
//! `--align colmap` the survey arrives as photos: COLMAP registers them into the latest posed
//! survey's model (old poses held) and writes the dataset PATH first
//! (`timeline::register_survey`); the residual is printed and kept. With `--segment` the survey may arrive as photos
//! alone: its photos are segmented first and the masks written into its dataset
//! (`timeline::segment_survey`), then it is added. The work is `timeline::add_survey`'s, the
//! app's "Add survey…" runs the same job.

use std::path::PathBuf;

use damage_twin::scene::sfm::PoseOptions;
use damage_twin::timeline::Twin;
use damage_twin::timeline::add_survey::{SegmentWith, SurveyToAdd, add_survey_job};
use damage_twin::timeline::survey::AlignMode;

use crate::cli::args::{JobArgs, LockArgs, drive, parse_survey_name};
use crate::cli::pose::{EngineArg, colmap_bar, show};
use crate::cli::segment::ModelArgs;

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
    #[command(flatten)]
    pub engine: EngineArg,
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
    let twin = super::open_to_write(&args.dir, &args.lock, "twin add-survey")?;
    if let Some(photos) = &args.photos {
        register_photos(&twin, &args, photos)?;
    }
    let segment = match args.segment {
        Some(model) => Some(SegmentWith {
            model,
            settings: args
                .model
                .settings(false, twin.project.settings.background)?,
        }),
        None => None,
    };
    let survey = SurveyToAdd {
        name: args.survey.clone(),
        date: args.date,
        dataset: args.dataset,
        align: args.align,
        segment,
        dataset_must_open: false,
    };
    let job = add_survey_job(twin, survey, args.job.options());
    let what = format!("adding survey {}", args.survey);
    let (twin, added) = drive(job, &what, args.job.quiet, |_| {})?;
    // The job is only cancelled by a client, and the CLI has none: an add that did not happen
    // is still said.
    let Some(added) = added else {
        anyhow::bail!(
            "adding survey {} was cancelled: nothing changed",
            args.survey
        );
    };
    for line in added.lines() {
        println!("{line}");
    }
    // The COLMAP registration's residual, as the commit kept it.
    if args.align == AlignMode::Colmap
        && let Some(record) = twin.load_registration(&args.survey)?
    {
        println!("{}", record.describe());
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
        engine: args.engine.engine,
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
