//! `damage-twin bench DATASET`: trains for a fixed number of steps and prints, as JSON, the time
//! per iteration by stage, the Gaussian count, peak memory and bytes per Gaussian. Uses the same
//! views, held-out rule and initialisation as `train`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use serde::Serialize;

use damage_twin::metrics::peak_rss_mb;
use damage_twin::splats::Splats;
use damage_twin::train::spec::TrainSpec;
use damage_twin::train::trainer::{StageTimes, Trainer};
use damage_twin::train::views::{InitialModel, initial_splats, load_views, split_views};

use super::train::{RunArgs, open_dataset};

#[derive(clap::Args, Debug)]
pub struct Args {
    pub dataset: PathBuf,
    #[arg(long, default_value_t = 500)]
    pub iters: u32,
    #[command(flatten)]
    pub run: RunArgs,
}

#[derive(Serialize)]
struct Bench {
    dataset: String,
    width: u32,
    height: u32,
    train_views: usize,
    iterations: u32,
    threads: usize,
    /// The SIMD build the CPU kernels ran (`DAMAGE_TWIN_SIMD` can lower it).
    simd: &'static str,
    seconds: f64,
    ms_per_iteration: f64,
    stage_ms_per_iteration: StageTimes,
    initial_gaussians: usize,
    gaussians: usize,
    peak_rss_mb: Option<f64>,
    /// Parameters only (what a saved model holds in memory).
    model_bytes_per_gaussian: usize,
    /// Parameters + gradients + Adam moments + density statistics.
    training_bytes_per_gaussian: usize,
    heldout_psnr: Option<f64>,
}

/// f32 values per Gaussian of the parameters.
fn floats_per_gaussian(splats: &Splats) -> usize {
    3 + 3 + 4 + 1 + splats.sh_coeffs() * 3 + splats.label_channels
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let body = || -> anyhow::Result<Bench> {
        let dataset = open_dataset(&args.dataset, args.run.background)?;
        let (train_idx, test_idx) =
            split_views(&dataset, &args.run.holdout.holdout()).map_err(anyhow::Error::msg)?;
        let views = load_views(&dataset, &train_idx, args.run.scale, false)?;
        let heldout = load_views(&dataset, &test_idx, args.run.scale, false)?;
        let init = InitialModel {
            sh_degree: args.run.sh_degree,
            label_channels: 0,
            random_points: args.run.init_points,
            seed: args.run.seed,
        };
        let splats = initial_splats(&dataset, &views, &init).context("initial Gaussians")?;
        let initial_gaussians = splats.len();
        let mut spec = TrainSpec::reconstruction(args.iters);
        spec.scale = args.run.scale;
        spec.sh_degree = args.run.sh_degree;
        spec.seed = args.run.seed;
        spec.background = args.run.background;
        let (width, height) = (views[0].image.width, views[0].image.height);
        let train_views = views.len();
        let mut trainer = Trainer::new(spec, splats, views)?;
        let started = Instant::now();
        while !trainer.is_done() {
            trainer.step();
        }
        let seconds = started.elapsed().as_secs_f64();
        let heldout_psnr = (!heldout.is_empty()).then(|| trainer.evaluate(&heldout).psnr);
        let steps = trainer.steps_done();
        let stages = trainer.timings().per_step_ms(steps);
        let splats = trainer.into_splats();
        let floats = floats_per_gaussian(&splats);
        Ok(Bench {
            dataset: args.dataset.display().to_string(),
            width,
            height,
            train_views,
            iterations: steps,
            threads: rayon::current_num_threads(),
            simd: damage_twin::simd::simd_level().name(),
            seconds,
            ms_per_iteration: seconds * 1000.0 / steps.max(1) as f64,
            stage_ms_per_iteration: stages,
            initial_gaussians,
            gaussians: splats.len(),
            peak_rss_mb: peak_rss_mb(),
            model_bytes_per_gaussian: floats * 4 + 8 + 2 + 1,
            // params + grads + 2 Adam moments, metadata, visibility, 2D-gradient norm, radius,
            // and the densifier's three statistics.
            training_bytes_per_gaussian: floats * 4 * 4 + 11 + 1 + 4 + 4 + 12,
            heldout_psnr,
        })
    };
    // In a pool of its own like a training job (`TrainJob::spawn_with`), so the bench times
    // the same thread setup; 0 threads means the default (RAYON_NUM_THREADS or every core).
    let bench = rayon::ThreadPoolBuilder::new()
        .num_threads(args.run.threads.unwrap_or(0))
        .build()
        .context("starting the thread pool")?
        .install(body)?;
    println!("{}", serde_json::to_string_pretty(&bench)?);
    Ok(())
}
