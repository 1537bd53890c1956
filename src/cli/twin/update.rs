//! `damage-twin twin update DIR --survey NAME [--strategy finetune|retrain]`: the twin of the
//! survey before NAME, updated with NAME's photos and masks (`timeline::update`), written as
//! NAME's model; every earlier survey's model stays as it was. On a partitioned twin (the model
//! before NAME merged from blocks) only the changed blocks are retrained, through an engine
//! (`update_blocks`).

use std::path::PathBuf;

use damage_twin::damage::refine::Strategy;
use damage_twin::timeline::blocks::update::partitioned_previous;
use damage_twin::timeline::update::{UpdateConfig, update_project_job};

use crate::cli::args::{JobArgs, LockArgs, ProjectScaleArgs, drive};

#[derive(clap::Args, Debug)]
pub struct Args {
    pub dir: PathBuf,
    #[arg(long)]
    pub survey: String,
    #[arg(long, default_value = "finetune")]
    pub strategy: Strategy,
    // `--scale`: the resolution the update trains at.
    #[command(flatten)]
    pub scale: ProjectScaleArgs,
    /// Training steps (default: 200, or 8 a training view for a survey of more than 25 views;
    /// `timeline::update::update_iterations`).
    #[arg(long)]
    pub iters: Option<u32>,
    /// Train on the photos as they are (no per-photo light compensation).
    #[arg(long)]
    pub no_appearance: bool,
    /// Each trained Gaussian's scale stays within this factor of its size before (0: unbounded).
    #[arg(long, default_value_t = damage_twin::timeline::update::UPDATE_MAX_SCALE_GROWTH)]
    pub max_scale_growth: f32,
    /// Train with gentler learning rates than a from-scratch run (the earlier survey's views keep
    /// their look better; new thin damage is learnt less: docs/TIMELINE.md).
    #[arg(long)]
    pub gentle_rates: bool,
    /// Do not seed Gaussians for new damage before training (`timeline::seed`).
    #[arg(long)]
    pub no_seeds: bool,
    /// Keep the earlier twin's near floaters of the new survey's cameras (frozen) instead of
    /// clearing them before training (docs/TIMELINE.md).
    #[arg(long)]
    pub keep_near_floaters: bool,
    /// A factor on the position, scale, rotation and opacity rates of the trained Gaussians that
    /// are only neighbours of damage; damage and seeds learn at full rates (0: full for all).
    #[arg(long, default_value_t = damage_twin::timeline::update::NEIGHBOUR_GEOMETRY_RATE)]
    pub neighbour_geometry_rate: f32,
    /// Stop once the hull loss has not improved by 1 % over two windows of this many steps in a
    /// row (0: run every step; docs/TIMELINE.md).
    #[arg(long, default_value_t = 0)]
    pub plateau_window: u32,
    /// Study oracle: draw the hulls from the survey's truth masks (synthetic surveys only), the
    /// upper bound of what full hull coverage of the new damage buys.
    #[arg(long)]
    pub truth_hulls: bool,
    /// The renderer that trains: cpu, gpu or auto (see `train --backend`).
    #[arg(long, default_value = "cpu")]
    pub backend: damage_twin::train::backend_choice::Backend,
    #[command(flatten)]
    pub job: JobArgs,
    #[command(flatten)]
    pub lock: LockArgs,
    // A partitioned twin's options: the blocks and the engine.
    #[command(flatten)]
    pub blocks: super::update_blocks::BlockArgs,
    /// Partitioned twin: the engine that trains the changed blocks (default: one local process).
    #[command(subcommand)]
    pub engine: Option<super::update_blocks::Engine>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    // Read now, locked only to record the result when the training ends (`record_update`).
    let twin = super::open_to_write(&args.dir, &args.lock, "twin update")?;
    twin.survey_index(&args.survey)?;
    if partitioned_previous(&twin, &args.survey)?.is_some() {
        return super::update_blocks::run(twin, &args);
    }
    let mut config = UpdateConfig::for_project(
        &twin,
        args.strategy,
        args.scale.or_project(&twin),
        args.iters,
        !args.no_appearance,
    );
    config.refine.max_scale_growth = (args.max_scale_growth > 0.0).then_some(args.max_scale_growth);
    config.refine.backend = args.backend;
    config.refine.neighbour_geometry_rate =
        (args.neighbour_geometry_rate > 0.0).then_some(args.neighbour_geometry_rate);
    config.refine.hulls_from_truth = args.truth_hulls;
    config.refine.stop_when_flat =
        (args.plateau_window > 0).then_some(damage_twin::train::plateau::Plateau {
            window: args.plateau_window,
            min_gain: 0.01,
            patience: 2,
        });
    if args.no_seeds {
        config.seeds = None;
    }
    config.clear_near_floaters = !args.keep_near_floaters;
    if args.gentle_rates {
        config.refine.lr = damage_twin::timeline::update::gentle_learning_rates();
    }
    // The update's model, metrics and training history are committed together by the job.
    let job = update_project_job(twin, args.survey.clone(), config, args.job.options());
    let (twin, outcome) = drive(job, "update", args.job.quiet, |_| {})?;
    let path = twin
        .model_path(&args.survey)?
        .map_or_else(|| twin.survey_dir(&args.survey), Ok)?;
    let r = &outcome.report;
    println!(
        "updated {} from {} in {:.0} s: {} new-damage Gaussians; held-out IoU {:?} → {:?}; model {}",
        r.survey,
        r.previous,
        r.seconds,
        r.new_damage_gaussians,
        r.refine.before.iou,
        r.refine.after.iou,
        path.display()
    );
    Ok(())
}
