//! `damage-twin study segment --model MODEL.onnx --data ../shared/data --out DIR`: the shared
//! crack model on the crack photos (IoU and precision / recall within 2 px at each scale and
//! tile size; seconds per megapixel on 1 and 2 threads) and on the demo building (its photos
//! segmented, a label-mode twin trained on them, both scored against the clean truth). Writes
//! `DIR/segment-study.json`, the chart `segment-study.png` / `.svg` and overlays
//! `segment-overlay-*.png`.

use std::path::PathBuf;

use anyhow::Context;

use damage_twin::segment::SegmentModel;
use damage_twin::studies::segment::chart::write_segment_chart;
use damage_twin::studies::segment::crack_sets::{
    crack_images, score_sets, speed, write_set_overlays,
};
use damage_twin::studies::segment::demo::run_demo;
use damage_twin::studies::segment::{SegmentStudy, SegmentStudyConfig};

use super::{read_saved, write_text};

#[derive(clap::Args, Debug)]
pub struct SegmentStudyArgs {
    /// The one-channel crack model (ONNX).
    #[arg(long)]
    pub model: PathBuf,
    /// The shared data folder (crackforest/, ipcshm_tunnel_welding_crack_samples/).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Folder of segment-study.json, the chart and the overlays.
    #[arg(long)]
    pub out: PathBuf,
    /// Where the demo building and its segmented masks are made (default: a folder in the
    /// system's temporary folder).
    #[arg(long)]
    pub work: Option<PathBuf>,
    /// crackforest photos scored (its first ones).
    #[arg(long, default_value_t = 20)]
    pub crackforest: usize,
    /// Demo building photo width and height, views and training iterations.
    #[arg(long, default_value_t = 480)]
    pub demo_width: u32,
    #[arg(long, default_value_t = 270)]
    pub demo_height: u32,
    #[arg(long, default_value_t = 16)]
    pub demo_views: usize,
    #[arg(long, default_value_t = 400)]
    pub demo_iters: u32,
    /// Skip the demo building (the crack photos only).
    #[arg(long)]
    pub no_demo: bool,
    /// Worker threads of the scoring and the demo's training (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Measure nothing: redraw the chart from `--out DIR/segment-study.json`.
    #[arg(long)]
    pub replot: bool,
}

pub fn run(args: SegmentStudyArgs) -> anyhow::Result<()> {
    if args.replot {
        let study: SegmentStudy = read_saved(&args.out, "segment-study.json")?;
        write_segment_chart(&args.out, "segment-study", &study)?;
        return Ok(());
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let config = SegmentStudyConfig {
        crackforest_images: args.crackforest,
        demo_width: args.demo_width,
        demo_height: args.demo_height,
        demo_views: args.demo_views,
        demo_iterations: args.demo_iters,
        ..SegmentStudyConfig::default()
    };
    let model = SegmentModel::open(&args.model, 1)?;
    let images = crack_images(&args.data, config.crackforest_images);
    if images.is_empty() {
        anyhow::bail!(
            "{}: no crack photos with truth masks found",
            args.data.display()
        );
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("the worker threads")?;
    let mut print = |line: String| println!("{line}");
    let crack_sets = pool.install(|| score_sets(&model, &images, &config, &mut print))?;
    let crackforest: Vec<_> = images
        .iter()
        .filter(|i| i.set == "crackforest")
        .cloned()
        .collect();
    let speed = speed(&model, &crackforest, &[1, 2])?;
    for row in &speed {
        println!(
            "{} thread(s): {:.3} s per megapixel, {:.2} images/s",
            row.threads, row.seconds_per_megapixel, row.images_per_second
        );
    }
    for path in pool.install(|| write_set_overlays(&model, &images, &args.out, config.threshold))? {
        println!("wrote {}", path.display());
    }
    let demo = if args.no_demo {
        None
    } else {
        let work = args
            .work
            .clone()
            .unwrap_or_else(|| std::env::temp_dir().join("damage-twin-segment-study"));
        Some(
            pool.install(|| run_demo(&model, &config, &work, &args.out, args.threads, &mut print))
                .map_err(anyhow::Error::msg)
                .context("the demo building")?,
        )
    };
    let study = SegmentStudy {
        config,
        model: args.model.display().to_string(),
        crack_sets,
        speed,
        demo,
    };
    let json = serde_json::to_string_pretty(&study).context("the study as JSON")?;
    write_text(&args.out, "segment-study.json", &json)?;
    for path in write_segment_chart(&args.out, "segment-study", &study)? {
        println!("wrote {}", path.display());
    }
    Ok(())
}
