//! `damage-twin compact MODEL DATASET --budget N --out M`: prunes a trained model to its N most
//! important Gaussians (blending weight over the dataset's training views, `train::importance`)
//! and fine-tunes the rest briefly; prints Gaussians and held-out PSNR before and after as JSON.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use glam::Vec3;
use serde::Serialize;

use damage_twin::damage::TrainMode;
use damage_twin::damage::assess::{EvalRequest, evaluate_model};
use damage_twin::damage::evaluate::DamageReadout;
use damage_twin::raster::RenderSettings;
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::splats::Splats;
use damage_twin::train::importance::{importance, prune_to};
use damage_twin::train::job::JobOptions;
use damage_twin::train::run::{TrainSetup, train};
use damage_twin::train::spec::{DensifyPolicy, TrainSpec};
use damage_twin::train::views::{load_views, split_views};

use super::args::{HoldoutArgs, drive, open_dataset, parse_background, parse_scale, read_model};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Trained model (3DGS PLY).
    pub model: PathBuf,
    /// The dataset it was trained on (importance and fine-tuning use its training views).
    pub dataset: PathBuf,
    /// Gaussians to keep: a count (`50000`) or a fraction of the model's (`0.5`).
    #[arg(long, value_parser = parse_budget)]
    pub budget: Budget,
    /// Where the compacted model is written (PLY, atomically).
    #[arg(long)]
    pub out: PathBuf,
    /// Fine-tuning steps after the prune (0: prune only).
    #[arg(long, default_value_t = 500)]
    pub iters: u32,
    /// Image scale of the training and held-out views: 1, 2, 4, 8, 0.25 or w<width>.
    #[arg(long, default_value = "1", value_parser = parse_scale)]
    pub scale: ImageScale,
    #[command(flatten)]
    pub holdout: HoldoutArgs,
    #[arg(long, default_value = "black", value_parser = parse_background)]
    pub background: Vec3,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// How many Gaussians to keep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    Count(usize),
    /// Of the model's own count, in (0, 1].
    Fraction(f64),
}

impl Budget {
    fn of(self, gaussians: usize) -> usize {
        match self {
            Budget::Count(n) => n,
            Budget::Fraction(f) => (gaussians as f64 * f).round() as usize,
        }
    }
}

/// A count (an integer ≥ 1) or a fraction in (0, 1].
pub fn parse_budget(text: &str) -> Result<Budget, String> {
    if let Ok(n) = text.parse::<usize>() {
        return if n >= 1 {
            Ok(Budget::Count(n))
        } else {
            Err("a budget of 0 Gaussians keeps nothing".into())
        };
    }
    match text.parse::<f64>() {
        // `!(f > 0)` also refuses NaN.
        Ok(f) if !(f > 0.0 && f <= 1.0) => Err(format!("budget fraction {text} is not in (0, 1]")),
        Ok(f) => Ok(Budget::Fraction(f)),
        Err(_) => Err(format!(
            "bad budget {text:?}: a count (50000) or a fraction of the model (0.5)"
        )),
    }
}

/// `train --budget`: a count only. A fraction would be of the count the same run reaches without
/// a budget, which is not known until that run has been made.
pub fn parse_train_budget(text: &str) -> Result<usize, String> {
    match parse_budget(text)? {
        Budget::Count(n) => Ok(n),
        Budget::Fraction(_) => Err(format!(
            "train --budget {text}: give a count; a fraction would be of the Gaussians an \
             unbudgeted run ends with, unknown before it runs (train once, then `compact \
             --budget {text}` its model, or pass that count)"
        )),
    }
}

#[derive(Serialize)]
struct Report {
    gaussians_before: usize,
    gaussians_after: usize,
    psnr_before: f64,
    /// Right after the prune, before fine-tuning.
    psnr_pruned: f64,
    psnr_after: f64,
    /// Size of the written PLY.
    bytes: u64,
    /// Importance, prune and fine-tuning (evaluations excluded).
    seconds: f64,
    iterations: u32,
}

/// Mean held-out PSNR of `splats` on the views `indices` of `dataset` (photos only).
pub fn heldout_psnr(
    dataset: &Dataset,
    splats: &Splats,
    indices: &[usize],
    scale: ImageScale,
    background: Vec3,
) -> anyhow::Result<f64> {
    let request = EvalRequest {
        indices: indices.to_vec(),
        scale,
        background,
        sh_degree: splats.sh_degree,
        photometric: true,
        half_appearance: false,
        readout: DamageReadout {
            mode: TrainMode::Rgb,
            ..DamageReadout::for_model(splats, Default::default())
        },
    };
    let scores = evaluate_model(dataset, splats, &request, &mut |_, _| {})?;
    Ok(scores.psnr.unwrap_or(f64::NAN))
}

/// How `compact_model` fine-tunes after the prune.
pub struct Finetune {
    /// Steps (0: prune only).
    pub iterations: u32,
    pub scale: ImageScale,
    pub background: Vec3,
    pub seed: u64,
    pub threads: Option<usize>,
    pub quiet: bool,
}

/// A compacted model and the seconds its importance, prune and fine-tune took.
pub struct Compacted {
    pub splats: Splats,
    pub seconds: f64,
}

/// Prunes `splats` to the `keep` with the most blending weight over the training views
/// `train_idx` of `dataset`, shows the pruned model to `on_pruned`, then fine-tunes it.
pub fn compact_model(
    dataset: &Dataset,
    mut splats: Splats,
    train_idx: &[usize],
    keep: usize,
    finetune: &Finetune,
    on_pruned: &mut dyn FnMut(&Splats) -> anyhow::Result<()>,
) -> anyhow::Result<Compacted> {
    let started = Instant::now();
    let views = load_views(dataset, train_idx, finetune.scale, false)
        .with_context(|| format!("loading the training views of {}", dataset.root.display()))?;
    let before = splats.len();
    let settings = RenderSettings::new(finetune.background, splats.sh_degree);
    let score = importance(&splats, &views, &settings);
    prune_to(&mut splats, &score, keep);
    let mut seconds = started.elapsed().as_secs_f64();
    eprintln!(
        "pruned {before} → {} Gaussians by importance over {} training views",
        splats.len(),
        views.len()
    );
    on_pruned(&splats)?;

    // A continuation, not a restart: the fixed set keeps its size (no densification) and moves
    // at the timeline update's gentle rates; labels are kept as they are.
    if finetune.iterations > 0 {
        let mut spec = TrainSpec::reconstruction(finetune.iterations);
        spec.densify = DensifyPolicy::Off;
        spec.groups.raw_labels = false;
        spec.sh_degree = splats.sh_degree;
        spec.sh_ramp_every = 1;
        spec.background = finetune.background;
        spec.seed = finetune.seed;
        spec.lr = damage_twin::timeline::update::gentle_learning_rates();
        let setup = TrainSetup {
            spec,
            splats,
            views,
            heldout: Vec::new(),
        };
        let outcome = drive(
            train(setup, JobOptions::headless(finetune.threads)),
            "fine-tuning",
            finetune.quiet,
            |_| {},
        )?;
        seconds += outcome.seconds;
        splats = Arc::try_unwrap(outcome.splats).unwrap_or_else(|shared| (*shared).clone());
    }
    Ok(Compacted { splats, seconds })
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let splats = read_model(&args.model)?;
    let dataset = Arc::new(open_dataset(&args.dataset, args.background)?);
    let (train_idx, test_idx) =
        split_views(&dataset, &args.holdout.holdout()).map_err(anyhow::Error::msg)?;
    let before = splats.len();
    let keep = args.budget.of(before);
    let psnr_before = heldout_psnr(&dataset, &splats, &test_idx, args.scale, args.background)?;

    let psnr_pruned = std::cell::Cell::new(f64::NAN);
    let compacted = compact_model(
        &dataset,
        splats,
        &train_idx,
        keep,
        &Finetune {
            iterations: args.iters,
            scale: args.scale,
            background: args.background,
            seed: args.seed,
            threads: args.threads,
            quiet: args.quiet,
        },
        &mut |pruned| {
            psnr_pruned.set(heldout_psnr(
                &dataset,
                pruned,
                &test_idx,
                args.scale,
                args.background,
            )?);
            Ok(())
        },
    )?;
    let splats = compacted.splats;
    let psnr_pruned = psnr_pruned.get();
    let psnr_after = heldout_psnr(&dataset, &splats, &test_idx, args.scale, args.background)?;

    damage_twin::scene::ply::write_splats(&args.out, &splats)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let bytes = std::fs::metadata(&args.out).map(|m| m.len()).unwrap_or(0);
    let report = Report {
        gaussians_before: before,
        gaussians_after: splats.len(),
        psnr_before,
        psnr_pruned,
        psnr_after,
        bytes,
        seconds: compacted.seconds,
        iterations: args.iters,
    };
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budgets_parse_as_counts_or_fractions() {
        assert_eq!(parse_budget("300"), Ok(Budget::Count(300)));
        assert_eq!(parse_budget("0.5"), Ok(Budget::Fraction(0.5)));
        assert_eq!(Budget::Fraction(0.5).of(301), 151);
        for bad in ["0", "1.5", "-0.2", "NaN", "lots"] {
            assert!(parse_budget(bad).is_err(), "{bad}");
        }
        assert!(parse_train_budget("0.5").is_err());
        assert_eq!(parse_train_budget("300"), Ok(300));
    }
}
