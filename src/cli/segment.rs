//! `damage-twin segment DATASET --model MODEL.onnx [--class crack | --classes LIST]`: damage masks
//! from the photos themselves (`segment`): every photo through an ONNX model in tiles, the masks
//! and 8-bit probabilities written beside the photos. `--from-probabilities` re-thresholds the
//! stored probabilities without the model. The model's settings are a group `twin add-survey
//! --segment` shares.

use std::path::PathBuf;

use anyhow::{Context, bail};
use glam::Vec3;

use damage_twin::scene::{DamageClass, ImageScale};
use damage_twin::segment::{
    Activation, ChannelOrder, PhotoSettings, Preprocess, SegmentSettings, SegmentSummary, Tiling,
    dataset_photos, masks_from_probabilities, parse_channel_classes, segment_job,
};

use crate::cli::args::{JobArgs, drive, open_dataset, parse_background, parse_scale};

/// How the model reads a photo and what its output means (shared with `twin add-survey
/// --segment`). The defaults are the shared crack model's: RGB in [0, 1], one probability
/// channel.
#[derive(clap::Args, Debug, Clone)]
pub struct ModelArgs {
    /// The damage class of a one-channel model.
    #[arg(long, default_value = "crack", conflicts_with = "classes")]
    pub class: String,
    /// One entry per output channel of a multi-class model, comma-separated: a class (crack,
    /// spalling, rebar) or `-` for a channel not written (background), e.g. `-,crack,spalling`.
    #[arg(long)]
    pub classes: Option<String>,
    /// The scale the photos are run at (1, 2, 4, 8, 0.5, … or w<width>); masks are written at
    /// the photo's own size.
    #[arg(long, default_value = "1", value_parser = parse_scale)]
    pub scale: ImageScale,
    /// Tile side in pixels of the scaled photo; larger photos run in overlapping tiles.
    #[arg(long, default_value_t = 512)]
    pub tile: u32,
    /// Overlap of neighbouring tiles in pixels (blended with a linear ramp).
    #[arg(long, default_value_t = 64)]
    pub overlap: u32,
    /// The model's input sides must be a multiple of this (inputs are padded up to it).
    #[arg(long, default_value_t = 16)]
    pub multiple: u32,
    /// A pixel is damage where its probability is at least this.
    #[arg(long, default_value_t = damage_twin::segment::DEFAULT_THRESHOLD)]
    pub threshold: f32,
    /// The model's channel order: rgb or bgr.
    #[arg(long, default_value = "rgb")]
    pub channels: ChannelOrder,
    /// Input range: 1 for [0, 1], 255 for [0, 255] (before mean and std).
    #[arg(long, default_value_t = 1.0)]
    pub range: f32,
    /// Per-channel mean subtracted, in the model's order (ImageNet: 0.485,0.456,0.406).
    #[arg(long, default_value = "0,0,0", value_parser = damage_twin::segment::preprocess::parse_triple)]
    pub mean: [f32; 3],
    /// Per-channel standard deviation divided by (ImageNet: 0.229,0.224,0.225).
    #[arg(long, default_value = "1,1,1", value_parser = damage_twin::segment::preprocess::parse_triple)]
    pub std: [f32; 3],
    /// What makes the output probabilities: none (already), sigmoid or softmax (logits).
    #[arg(long, default_value = "none")]
    pub activation: Activation,
}

impl ModelArgs {
    /// The class of each output channel.
    pub fn channel_classes(&self) -> anyhow::Result<Vec<Option<DamageClass>>> {
        let list = self.classes.as_deref().unwrap_or(&self.class);
        Ok(parse_channel_classes(list)?)
    }

    /// The settings of a run writing (or refusing to overwrite, unless `overwrite`) masks.
    pub fn settings(
        &self,
        overwrite: bool,
        background: [f32; 3],
    ) -> anyhow::Result<SegmentSettings> {
        Ok(SegmentSettings {
            classes: self.channel_classes()?,
            photo: PhotoSettings {
                preprocess: Preprocess {
                    order: self.channels,
                    range: self.range,
                    mean: self.mean,
                    std: self.std,
                    activation: self.activation,
                },
                scale: self.scale,
                tiling: Tiling {
                    tile: self.tile,
                    overlap: self.overlap,
                    multiple: self.multiple,
                },
            },
            threshold: self.threshold,
            overwrite,
            background,
        })
    }
}

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The dataset whose photos are segmented (masks/ and probabilities/ are written in it).
    pub dataset: PathBuf,
    /// The ONNX model: input [1, 3, H, W], output [1, C, H, W] (C: one channel per class).
    #[arg(long, required_unless_present = "from_probabilities")]
    pub model: Option<PathBuf>,
    #[command(flatten)]
    pub model_args: ModelArgs,
    /// Replace masks and probabilities already there.
    #[arg(long)]
    pub overwrite: bool,
    /// Rewrite the masks from the stored probabilities at --threshold, without the model.
    #[arg(long, conflicts_with = "model")]
    pub from_probabilities: bool,
    /// Background RGBA photos are composited on: white, black or r,g,b in [0, 1].
    #[arg(long, default_value = "black", value_parser = parse_background)]
    pub background: Vec3,
    #[command(flatten)]
    pub job: JobArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let dataset = open_dataset(&args.dataset, args.background)?;
    let photos = dataset_photos(&dataset);
    let settings = args
        .model_args
        .settings(args.overwrite, args.background.to_array())?;
    let summary = if args.from_probabilities {
        let classes = settings.written_classes();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(args.job.threads.unwrap_or(0))
            .build()
            .context("the worker threads")?;
        pool.install(|| {
            masks_from_probabilities(&dataset.root, &photos, &classes, settings.threshold)
        })
        .context("re-thresholding the stored probabilities")?
    } else {
        let Some(model) = args.model.clone() else {
            bail!("--model is needed (or --from-probabilities)");
        };
        let channels = settings.classes.len();
        let job = segment_job(
            model,
            channels,
            dataset.root.clone(),
            photos,
            settings,
            args.job.options(),
        );
        drive(job, "segmentation", args.job.quiet, |_| {})?
    };
    print_summary(&summary, args.job.thread_count(), &dataset.root);
    Ok(())
}

/// The run in one line per fact: photos, speed, damage share per class.
pub fn print_summary(summary: &SegmentSummary, threads: usize, root: &std::path::Path) {
    for line in summary.lines(threads, root) {
        println!("{line}");
    }
}
