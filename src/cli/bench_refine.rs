//! `damage-twin bench DATASET --refine MODEL`: what a fine-tune step of a coarse twin costs
//! against a full-image step of the same model, both timed interleaved in this process
//! (`damage::refine::StepCosts`), so the ratio holds on a busy host; printed by stage, with the
//! pixels each renders, then as JSON.

use std::path::Path;
use std::sync::Arc;

use anyhow::Context;

use damage_twin::damage::evaluate::DamageReadout;
use damage_twin::damage::refine::{RefineConfig, StepCosts, refine_job};
use damage_twin::damage::select::SelectConfig;
use damage_twin::train::job::JobOptions;
use damage_twin::train::trainer::StageTimes;

use super::args::{drive, open_dataset, read_model};
use super::bench::Args;

pub fn run(model_path: &Path, args: &Args) -> anyhow::Result<()> {
    let model = Arc::new(read_model(model_path)?);
    let dataset = Arc::new(open_dataset(&args.dataset, args.run.images.background)?);
    let readout = DamageReadout::for_model(&model, Default::default());
    let config = RefineConfig {
        select: SelectConfig {
            mode: readout.mode,
            palette: readout.palette,
            colour_tolerance: readout.tolerance,
            ..SelectConfig::default()
        },
        scale: args.run.images.scale,
        holdout: args.run.holdout.holdout(),
        background: args.run.images.background,
        // The comparison is timed before the run: one step suffices.
        iterations: 1,
        cost_rounds: args.rounds.max(1),
        ..RefineConfig::default()
    };
    let job = refine_job(dataset, model, config, JobOptions::headless(args.threads));
    let outcome = drive(job, "refinement benchmark", true, |_| {})?;
    let costs = outcome
        .report
        .step_costs
        .as_ref()
        .context("the refinement benchmark timed no steps")?;
    print!("{}", stage_table(costs));
    println!("{}", serde_json::to_string_pretty(costs)?);
    Ok(())
}

/// One stage's milliseconds in a step's times.
type StageOf = fn(&StageTimes) -> f64;

/// The two steps side by side, stage by stage, each stage's share of the full step, and the
/// pixel counts.
fn stage_table(c: &StepCosts) -> String {
    let stages: [(&str, StageOf); 9] = [
        ("project", |t| t.project),
        ("sort", |t| t.sort),
        ("rasterize", |t| t.rasterize),
        ("loss", |t| t.loss),
        ("rasterize backward", |t| t.rasterize_backward),
        ("project backward", |t| t.project_backward),
        ("optimizer", |t| t.optimizer),
        ("densify", |t| t.densify),
        ("total", |t| t.total),
    ];
    let full_total = c.full_ms.total.max(f64::MIN_POSITIVE);
    let mut s = format!(
        "{} views, {} timed steps of each, interleaved\n{:<20} {:>12} {:>12} {:>14}\n",
        c.views, c.steps, "ms per step", "refinement", "full image", "% of full step"
    );
    for (name, get) in stages {
        let (r, f) = (get(&c.refine_ms), get(&c.full_ms));
        s += &format!(
            "{name:<20} {r:>12.2} {f:>12.2} {:>13.2}%\n",
            100.0 * r / full_total
        );
    }
    let share = |v: f64| 100.0 * v / c.full_pixels.max(1.0);
    s += &format!(
        "pixels per step: {:.0} full image; region {:.0} ({:.1} %), its tiles {:.0} ({:.1} %), \
         its SSIM reads {:.0} ({:.1} %)\n",
        c.full_pixels,
        c.region_pixels,
        share(c.region_pixels),
        c.region_tile_pixels,
        share(c.region_tile_pixels),
        c.ssim_pixels,
        share(c.ssim_pixels),
    );
    // The yardstick: a refinement step's cost against its region's pixel share.
    s += &format!(
        "refinement step {:.1} % of a full step = {:.2} × the region's pixel share\n",
        100.0 * c.share,
        100.0 * c.share / share(c.region_pixels).max(f64::MIN_POSITIVE),
    );
    s
}
