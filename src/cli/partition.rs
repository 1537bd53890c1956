//! `damage-twin partition DATASET --out PLAN`: cuts a posed dataset into blocks along its long
//! axis (`blocks::partition`) and writes the plan folder: `plan.json`, one `block-KKK/manifest.json`
//! per block and `blocks.png`, the blocks from above.

use std::path::PathBuf;

use anyhow::Context;

use damage_twin::blocks::partition::{PartitionConfig, Split, partition};
use damage_twin::blocks::picture::save_plan_picture;
use damage_twin::blocks::plan::{BlockTraining, ContextTraining};
use damage_twin::blocks::write_plan_folder;
use damage_twin::damage::TrainMode;

use super::args::{ImageArgs, open_dataset};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Dataset folder (COLMAP, transforms.json); every node must see it at the same path.
    pub dataset: PathBuf,
    /// The plan folder (the shared directory the blocks' results go into).
    #[arg(long)]
    pub out: PathBuf,
    /// Number of blocks along the long axis.
    #[arg(long, default_value_t = 4)]
    pub blocks: usize,
    /// grid (equal lengths) or balanced (equal numbers of points).
    #[arg(long, default_value = "grid")]
    pub split: Split,
    /// Margin on each side of a block, as a fraction of the shortest block's length.
    #[arg(long, default_value_t = 0.2)]
    pub margin: f32,
    /// Half width of the seam band the merge scores, as a fraction of the margin.
    #[arg(long, default_value_t = 0.5)]
    pub band: f32,
    /// A photo joins a block when this share of the points it sees lie in the block's enlarged box.
    #[arg(long, default_value_t = damage_twin::blocks::partition::DEFAULT_MIN_SHARE)]
    pub min_share: f32,
    /// Blocks seeing fewer training photos are skipped.
    #[arg(long, default_value_t = 3)]
    pub min_photos: usize,
    /// The whole run's steps this plan matches: each block trains this × its photos / all
    /// training photos (the same steps per photo as one run of this many steps).
    #[arg(long, default_value_t = 7000)]
    pub iters: u32,
    #[command(flatten)]
    pub images: ImageArgs,
    #[arg(long, default_value_t = 3)]
    pub sh_degree: u32,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// label or rgb.
    #[arg(long, default_value = "label")]
    pub mode: TrainMode,
    /// Every n-th view is held out (the merge's seam report scores on them).
    #[arg(long, default_value_t = 8)]
    pub test_every: usize,
    /// Steps of a coarse whole-scene context run trained before the blocks (`train-block
    /// --context`), rendered frozen behind each block and kept by the merge outside every
    /// block's box (the sky, the far ground); 0: no context.
    #[arg(long, default_value_t = 0)]
    pub context_iters: u32,
    /// The context run's image scale (1, 2, 4, 8, … or w<width>).
    #[arg(long, default_value = "2")]
    pub context_scale: String,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.test_every == 0 {
        anyhow::bail!("--test-every must be at least 1");
    }
    let dataset_path = std::fs::canonicalize(&args.dataset)
        .with_context(|| format!("opening dataset {}", args.dataset.display()))?;
    let dataset = open_dataset(&dataset_path, args.images.background)?;
    let holdout = damage_twin::train::views::Holdout::Auto {
        every: args.test_every,
    };
    let (train, _) =
        damage_twin::train::views::split_views(&dataset, &holdout).map_err(anyhow::Error::msg)?;
    let context = (args.context_iters > 0).then(|| ContextTraining {
        iters: args.context_iters,
        scale: args.context_scale.clone(),
    });
    if context.as_ref().is_some_and(|c| c.image_scale().is_none()) {
        anyhow::bail!(
            "--context-scale {:?} is not an image scale (1, 2, 4, 8, 0.5, … or w<width>)",
            args.context_scale
        );
    }
    let config = PartitionConfig {
        blocks: args.blocks,
        split: args.split,
        margin_fraction: args.margin,
        band_fraction: args.band,
        min_share: args.min_share,
        min_photos: args.min_photos,
        training: BlockTraining {
            scale: args.images.scale.to_string(),
            mode: args.mode,
            steps_per_photo: args.iters as f64 / train.len().max(1) as f64,
            seed: args.seed,
            sh_degree: args.sh_degree,
            background: args.images.background.to_array(),
            test_every: args.test_every,
        },
        context,
    };
    let plan = partition(&dataset, &dataset_path, &config)
        .map_err(|e| anyhow::anyhow!("{}: {e}", dataset_path.display()))?;
    write_plan_folder(&args.out, &plan)
        .with_context(|| format!("writing plan {}", args.out.display()))?;
    let picture = args.out.join("blocks.png");
    save_plan_picture(&picture, &plan, &dataset)?;
    for block in &plan.blocks {
        let state = match &block.skipped {
            Some(why) => format!("skipped: {why}"),
            None => format!(
                "{} photos, {} steps",
                block.photos.len(),
                plan.training.steps_for(block.photos.len())
            ),
        };
        println!(
            "block {}: [{:.2}, {:.2}) m along the long axis, {state}",
            block.index, block.start, block.end
        );
    }
    if let Some(context) = &plan.context {
        println!(
            "context: {} steps over all training photos at scale {} (train-block --context, before the blocks)",
            context.iters, context.scale
        );
    }
    println!(
        "plan {} (margin {:.2} m, seam band ±{:.2} m); picture {}",
        args.out.join("plan.json").display(),
        plan.margin,
        plan.seam_band,
        picture.display()
    );
    Ok(())
}
