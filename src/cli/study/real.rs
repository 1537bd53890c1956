//! `damage-twin study real CAPTURE_OR_STAMPED --out DIR`: on a capture with damage stamped onto
//! its photos (docs/STAMP.md; a plain capture is stamped first with `stamp`'s defaults), what the
//! demo building gets: the crack model's masks and their per-photo errors, a label-mode twin on
//! the truth masks, its fine-tune, a twin on the model's masks and the errors it corrects, change
//! detection against survey 2 and the measured quantities against the truth. Writes
//! `DIR/real-study.json` and the chart `real-study.png` / `.svg`.

use std::path::PathBuf;

use anyhow::Context;

use damage_twin::segment::SegmentModel;
use damage_twin::studies::real::chart::write_real_chart;
use damage_twin::studies::real::{RealStudy, RealStudyConfig, Segmenter, run_real};
use damage_twin::synth::stamp::{StampParams, stamp};

use super::{read_saved, write_text};

#[derive(clap::Args, Debug)]
pub struct RealStudyArgs {
    /// A stamped capture (`damage-twin stamp`'s output: survey-1/, survey-2/) or a posed
    /// capture to stamp first.
    pub capture: PathBuf,
    /// Folder of real-study.json and the chart.
    #[arg(long)]
    pub out: PathBuf,
    /// The one-channel crack model (ONNX).
    #[arg(
        long,
        default_value = "../shared/data/crack_unet_crackpot/crack_unet.onnx"
    )]
    pub model: PathBuf,
    /// Where the segmented masks (and a capture's stamped copy) are written (default: a folder
    /// in the system's temporary folder).
    #[arg(long)]
    pub work: Option<PathBuf>,
    /// Masks a segmenter already made (`DIR/masks/crack/<photo>.png` for every photo of
    /// survey 1, e.g. `damage-twin segment` run on a copy): scored instead of running --model.
    #[arg(long)]
    pub masks: Option<PathBuf>,
    /// Crack photos a plain capture is stamped with.
    #[arg(
        long = "crack-photos",
        num_args = 1..,
        default_values = ["../shared/data/crackforest", "../shared/data/ipcshm_tunnel_welding_crack_samples/tunnel"]
    )]
    pub crack_photos: Vec<PathBuf>,
    /// The twins train at 1/SCALE of the photos' size.
    #[arg(long, default_value_t = RealStudyConfig::default().scale)]
    pub scale: u32,
    #[arg(long, default_value_t = RealStudyConfig::default().iterations)]
    pub iters: u32,
    /// Fine-tune steps at the photos' size (0: none).
    #[arg(long, default_value_t = RealStudyConfig::default().fine_iterations)]
    pub fine_iters: u32,
    #[arg(long, default_value_t = RealStudyConfig::default().threshold)]
    pub threshold: f32,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Measure nothing: redraw the chart from `--out DIR/real-study.json`.
    #[arg(long)]
    pub replot: bool,
}

pub fn run(args: RealStudyArgs) -> anyhow::Result<()> {
    if args.replot {
        let study: RealStudy = read_saved(&args.out, "real-study.json")?;
        write_real_chart(&args.out, "real-study", &study)?;
        return Ok(());
    }
    if args.scale == 0 {
        anyhow::bail!("--scale 0: the twins' scale is a factor of 1 or more");
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let work = args
        .work
        .clone()
        .unwrap_or_else(|| std::env::temp_dir().join("damage-twin-real-study"));
    let stamped = if args.capture.join("survey-1").join("truth").is_dir() {
        args.capture.clone()
    } else {
        let out = work.join("stamped");
        println!("stamping {} into {}", args.capture.display(), out.display());
        let params = StampParams::new(&args.capture, &out, args.crack_photos.clone());
        stamp(&params, &|_, _| {})
            .with_context(|| format!("stamping damage onto {}", args.capture.display()))?;
        out
    };
    let config = RealStudyConfig {
        scale: args.scale,
        iterations: args.iters,
        fine_iterations: args.fine_iters,
        threshold: args.threshold,
    };
    let model = match &args.masks {
        Some(_) => None,
        None => Some(SegmentModel::open(&args.model, 1)?),
    };
    let segmented = work.join("segmented");
    let (segmenter, name) = match (&model, &args.masks) {
        (Some(model), _) => (
            Segmenter::Model(model, &segmented),
            args.model.display().to_string(),
        ),
        (None, Some(masks)) => (
            Segmenter::Masks(masks),
            format!("masks in {}", masks.display()),
        ),
        (None, None) => unreachable!("a model is opened when no masks are given"),
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("the worker threads")?;
    let mut print = |line: String| println!("{line}");
    let study = pool
        .install(|| {
            run_real(
                &stamped,
                segmenter,
                &name,
                &config,
                args.threads,
                &mut print,
            )
        })
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("the real-photo study on {}", stamped.display()))?;
    let json = serde_json::to_string_pretty(&study).context("the study as JSON")?;
    write_text(&args.out, "real-study.json", &json)?;
    for path in write_real_chart(&args.out, "real-study", &study)? {
        println!("wrote {}", path.display());
    }
    Ok(())
}
