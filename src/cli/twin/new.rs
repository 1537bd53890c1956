//! `damage-twin twin new DIR --survey NAME --date YYYY-MM-DD --dataset PATH [--model PLY]`:
//! a twin project whose first survey is `PATH`, with the given model or one trained now (a
//! coarse label-mode twin by default: the hierarchy starts coarse and refines the damage).

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context;

use damage_twin::damage::setup::{COARSE_SCALE, RunConfig, train_job};
use damage_twin::scene::ImageScale;
use damage_twin::scene::sfm::Georeference;
use damage_twin::timeline::Twin;
use damage_twin::timeline::blocks::record_plan;
use damage_twin::timeline::record::record_training;
use damage_twin::timeline::update::tag_damage;
use damage_twin::train::history::History;

use crate::cli::args::{
    JobArgs, LockArgs, drive, open_dataset, parse_scale, parse_survey_name, read_model,
};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The project folder (created; must not hold a project yet).
    pub dir: PathBuf,
    /// The survey's name, also its folder's: ASCII letters, digits, `-`, `_`, `.`.
    #[arg(long, value_parser = parse_survey_name)]
    pub survey: String,
    /// The survey's date, YYYY-MM-DD.
    #[arg(long)]
    pub date: String,
    /// The survey's dataset folder.
    #[arg(long)]
    pub dataset: PathBuf,
    /// The survey's model; without one, a model is trained.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// The block plan the model was merged from (`merge PLAN`): a partitioned twin, which
    /// `twin detect` and `twin update` treat block by block (docs/CLUSTER.md).
    #[arg(long, requires = "model")]
    pub plan: Option<PathBuf>,
    /// The project's scale (`twin update` and `twin detect` work at it unless given
    /// `--scale`), and the training scale when no model is given (4: 240×135 of a 960×540
    /// survey).
    #[arg(long, default_value_t = COARSE_SCALE, value_parser = parse_scale)]
    pub scale: ImageScale,
    /// Training iterations when no model is given.
    #[arg(long, default_value_t = 3000)]
    pub iters: u32,
    #[command(flatten)]
    pub job: JobArgs,
    #[command(flatten)]
    pub lock: LockArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut twin = Twin::create(&args.dir)?.with_writer(args.lock.writer("twin new"));
    twin.add_survey(&args.survey, &args.date, &args.dataset)?;
    twin.project.settings.scale = args.scale;
    // A dataset posed from GPS or control points (`damage-twin pose`) carries its metres: the
    // project's one scale is set from it, so no `set-scale` is needed.
    if let Some(georef) = Georeference::read(&args.dataset)? {
        twin.project.settings.metres_per_unit = Some(georef.metres_per_unit());
        println!(
            "metres from the dataset's georeference ({:?}): {:.5} m per unit, residual {:.2} m RMS",
            georef.source,
            georef.metres_per_unit(),
            georef.rms_m
        );
        if let Some(why) = &georef.model_doubt {
            eprintln!("warning: the dataset's poses are in doubt: {why}");
        }
    }
    let (mut model, trained) = match &args.model {
        Some(path) => (read_model(path)?, None),
        None => {
            let dataset = Arc::new(open_dataset(&args.dataset, glam::Vec3::ZERO)?);
            let config = RunConfig {
                scale: args.scale,
                iterations: args.iters,
                ..RunConfig::default()
            };
            let (mode, scale) = (config.mode, config.scale);
            let job = train_job(dataset, config, args.job.options());
            let started = std::time::Instant::now();
            let mut history = History::default();
            let outcome = drive(job, "training", args.job.quiet, |p| {
                history.record_progress(p, started.elapsed().as_secs_f64())
            })?;
            history.record_final(
                outcome.heldout.as_ref().map(|s| s.psnr),
                started.elapsed().as_secs_f64(),
            );
            (
                (*outcome.splats).clone(),
                Some((outcome, mode, scale, history)),
            )
        }
    };
    // The first survey's damage is first seen in it.
    tag_damage(&mut model, 0);
    // Every file is written under the project's lock, after checking that no other `twin new`
    // made a project in this folder while this one trained.
    let path = twin
        .commit(|twin| {
            if let Some((outcome, mode, scale, history)) = &trained {
                record_training(twin, &args.survey, outcome, *mode, *scale, Some(history))?;
            }
            if let Some(plan) = &args.plan {
                record_plan(twin, &args.survey, plan)?;
            }
            twin.save_model(&args.survey, &model)
        })
        .with_context(|| format!("writing {}", twin.file().display()))?;
    println!(
        "created {} with survey {} ({} Gaussians in {})",
        twin.file().display(),
        args.survey,
        model.len(),
        path.display()
    );
    Ok(())
}
