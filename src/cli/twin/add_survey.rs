//! `damage-twin twin add-survey DIR --survey NAME --date YYYY-MM-DD --dataset PATH
//! [--align same-frame|joint]`: a later survey placed in the twin's frame; `joint` reports the
//! registration's residual.

use std::path::PathBuf;

use damage_twin::timeline::survey::AlignMode;

use crate::cli::args::{LockArgs, parse_survey_name};

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
    #[command(flatten)]
    pub lock: LockArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut twin = super::open_to_write(&args.dir, &args.lock, "twin add-survey")?;
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
        None => println!("added survey {} (same frame)", args.survey),
    }
    Ok(())
}
