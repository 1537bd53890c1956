//! `damage-twin twin add-survey DIR --survey NAME --date YYYY-MM-DD --dataset PATH
//! [--align same-frame|joint] [--segment MODEL.onnx]`: a later survey placed in the twin's frame;
//! `joint` reports the registration's residual. With `--segment` the survey may arrive as photos
//! alone: its photos are segmented first and the masks written into its dataset
//! (`timeline::segment_survey`), then it is added. The work is `timeline::add_survey`'s, the
//! app's "Add survey…" runs the same job.

use std::path::PathBuf;

use damage_twin::timeline::add_survey::{SegmentWith, SurveyToAdd, add_survey_job};
use damage_twin::timeline::survey::AlignMode;

use crate::cli::args::{JobArgs, LockArgs, drive, parse_survey_name};
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
    /// survey's images and the new ones, registered through the images they share.
    #[arg(long, default_value = "same-frame")]
    pub align: AlignMode,
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
    let (_, added) = drive(job, &what, args.job.quiet, |_| {})?;
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
    Ok(())
}
