//! `damage-twin compact MODEL DATASET --budget N --out M`: prunes a trained model to its N most
//! important Gaussians (blending weight over the dataset's training views, `train::importance`)
//! and fine-tunes the rest briefly; prints Gaussians and held-out PSNR before and after as JSON.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context;
use glam::Vec3;
use serde::Serialize;

use damage_twin::damage::compact::{CompactConfig, compact_job, heldout_psnr};
use damage_twin::scene::ImageScale;
use damage_twin::train::job::JobOptions;
use damage_twin::train::views::split_views;

use super::args::{
    HoldoutArgs, drive, open_dataset, parse_background, parse_scale, parse_threads, read_model,
};

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
    #[arg(long, value_parser = parse_threads)]
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

impl std::fmt::Display for Budget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Budget::Count(n) => write!(f, "{n}"),
            Budget::Fraction(x) => write!(f, "{x}"),
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

pub fn run(args: Args) -> anyhow::Result<()> {
    let splats = read_model(&args.model)?;
    let before = splats.len();
    // A fraction that rounds to no Gaussian would write an empty model and exit 0.
    let keep = args.budget.of(before);
    if keep == 0 {
        anyhow::bail!(
            "--budget {}: keeps 0 of the {before} Gaussians of {}; keep at least one",
            args.budget,
            args.model.display()
        );
    }
    let dataset = Arc::new(open_dataset(&args.dataset, args.background)?);
    let holdout = args.holdout.holdout();
    let (_, test_idx) = split_views(&dataset, &holdout).map_err(anyhow::Error::msg)?;
    let psnr = |splats: &_| -> anyhow::Result<f64> {
        Ok(heldout_psnr(
            &dataset,
            splats,
            &test_idx,
            args.scale,
            args.background,
        )?)
    };
    let psnr_before = psnr(&splats)?;
    let config = CompactConfig {
        keep,
        iterations: args.iters,
        scale: args.scale,
        holdout,
        background: args.background,
        seed: args.seed,
        keep_pruned: true,
    };
    let job = compact_job(
        dataset.clone(),
        splats,
        config,
        JobOptions::headless(args.threads),
    );
    let compacted = drive(job, "compaction", args.quiet, |_| {})?;
    let psnr_pruned = match &compacted.pruned {
        Some(pruned) => psnr(pruned)?,
        None => f64::NAN,
    };
    let splats = compacted.splats;
    let psnr_after = psnr(&splats)?;

    damage_twin::splats::ply::write_splats(&args.out, &splats)
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
