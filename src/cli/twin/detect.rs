//! `damage-twin twin detect DIR --survey NAME [--json]`: the twin as of the survey before NAME,
//! rendered at NAME's poses, against NAME's masks: change maps (`surveys/NAME/changes/<view>.png`:
//! old damage in its class colour, new damage in the new-damage colour, damage no longer seen in
//! cyan) and `changes.json`, with precision and recall against `truth/new-damage` where present.

use std::path::PathBuf;

use damage_twin::timeline::blocks::changed::MIN_CHANGED_PIXELS;
use damage_twin::timeline::changes::OLD_DAMAGE_THRESHOLD;
use damage_twin::timeline::detect_survey::{DetectOptions, detect_survey};

use crate::cli::args::{LockArgs, ProjectScaleArgs};

#[derive(clap::Args, Debug)]
pub struct Args {
    pub dir: PathBuf,
    #[arg(long)]
    pub survey: String,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    // `--scale`: the resolution changes are found at.
    #[command(flatten)]
    pub scale: ProjectScaleArgs,
    /// New blobs lying wholly within this many pixels of old damage of their class are old
    /// damage seen shifted (misregistration, blur); growth reaching beyond is kept (0: off).
    #[arg(long, default_value_t = damage_twin::timeline::detect_survey::DEFAULT_BAND_PX)]
    pub band: u32,
    /// New-damage blobs smaller than this are dropped (pixels at the detection scale).
    #[arg(long, default_value_t = 0)]
    pub min_area: usize,
    /// Also drop candidates the earlier survey's own masks show at the same surface point
    /// (off by default: on the demo it removes growth next to old damage, docs/TIMELINE.md).
    #[arg(long)]
    pub earlier: bool,
    /// Earlier-survey check: mask pixels within this distance (pixels at the detection scale)
    /// of a candidate's surface point count as the earlier survey showing it.
    #[arg(long, default_value_t = 2)]
    pub earlier_radius: u32,
    /// Add the vote in 3D over the twin's Gaussians (off by default: on a coarse twin it drops
    /// thin new damage, docs/TIMELINE.md).
    #[arg(long)]
    pub vote: bool,
    /// Label mode: the class probability above which the twin's render is old damage.
    #[arg(long, default_value_t = OLD_DAMAGE_THRESHOLD)]
    pub old_threshold: f32,
    #[command(flatten)]
    pub lock: LockArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    // Read now, locked only to record the change maps at the end (`record_changes`).
    let mut twin = super::open_to_write(&args.dir, &args.lock, "twin detect")?;
    let options = DetectOptions {
        scale: args.scale.or_project(&twin),
        band_px: args.band,
        min_area_px: args.min_area,
        earlier: args.earlier,
        earlier_radius: args.earlier_radius,
        vote: args.vote,
        old_threshold: args.old_threshold,
    };
    let summary = detect_survey(&mut twin, &args.survey, &options, &mut |_, _| {})?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "{} views of {} against the twin of {}; change maps in {}",
            summary.views,
            args.survey,
            summary.twin_of,
            summary.folder.display()
        );
        for (class, f) in &summary.new_damage {
            let truth = match (f.precision, f.recall, f.iou) {
                (Some(p), Some(r), Some(i)) => {
                    format!("  precision {p:.3}  recall {r:.3}  IoU {i:.3}")
                }
                _ => String::new(),
            };
            println!("  new {class:<9} {:>8} px{truth}", f.pixels);
        }
        if let Some(blocks) = &summary.blocks {
            let changed = blocks.changed(MIN_CHANGED_PIXELS);
            println!(
                "blocks changed (at least {MIN_CHANGED_PIXELS} changed px): {changed:?}; `twin update` retrains them"
            );
            for b in &blocks.blocks {
                println!(
                    "  block {:>3}: {:>8} px new, {:>8} px gone",
                    b.block, b.new_pixels, b.gone_pixels
                );
            }
            if blocks.unplaced_pixels > 0 {
                println!("  on no surface: {} px", blocks.unplaced_pixels);
            }
        }
    }
    Ok(())
}
