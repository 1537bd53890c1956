//! `damage-twin inspect PATH [--json]`: what a dataset folder holds (format, cameras, images,
//! registered views, points, resolutions, camera models, masks, warnings), as text or one JSON
//! object. Only reports what `Dataset::open` found; reads no pixels.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;
use serde::Serialize;

use damage_twin::damage::DamageClass;
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{Dataset, DatasetFormat};

#[derive(clap::Args)]
pub struct Args {
    /// Dataset folder (COLMAP `sparse/` + `images/`, `transforms.json`, NeRF-synthetic).
    pub path: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The report, in the JSON shape `--json` prints.
#[derive(Serialize)]
pub struct Report {
    pub format: DatasetFormat,
    pub cameras: usize,
    /// Image files found on disk.
    pub images: usize,
    /// Images with a pose and an existing file.
    pub registered: usize,
    pub points: usize,
    /// `WIDTHxHEIGHT` → number of views.
    pub resolutions: BTreeMap<String, usize>,
    pub camera_models: BTreeMap<String, usize>,
    /// Views per split (`train`, `test`, `unspecified`).
    pub splits: BTreeMap<&'static str, usize>,
    /// Views whose images are undistorted on load.
    pub distorted: usize,
    pub masks: BTreeMap<String, usize>,
    /// Registered views with an ignore mask (`masks/<image file name>.png`).
    pub ignore_masks: usize,
    pub warnings: Vec<String>,
}

impl Report {
    pub fn new(dataset: &Dataset) -> Report {
        let mut resolutions = BTreeMap::new();
        for v in &dataset.views {
            let k = v.camera.intrinsics;
            *resolutions
                .entry(format!("{}x{}", k.width, k.height))
                .or_insert(0) += 1;
        }
        Report {
            format: dataset.format,
            cameras: dataset.camera_count,
            images: dataset.image_files,
            registered: dataset.views.len(),
            points: dataset.points.as_ref().map_or(0, |p| p.len()),
            resolutions,
            camera_models: dataset.camera_models.clone(),
            splits: damage_twin::scene::transforms::split_counts(&dataset.views),
            distorted: dataset
                .views
                .iter()
                .filter(|v| v.distortion.is_some())
                .count(),
            // Every class is listed, 0 when no mask was found, so the keys never vary.
            masks: DamageClass::ALL
                .iter()
                .map(|c| {
                    (
                        c.id().to_owned(),
                        dataset.mask_counts.get(c).copied().unwrap_or(0),
                    )
                })
                .collect(),
            ignore_masks: dataset.ignore_mask_count(),
            warnings: dataset.warnings.clone(),
        }
    }

    fn print_text(&self, path: &std::path::Path) {
        let list = |m: &BTreeMap<String, usize>| {
            if m.is_empty() {
                "none".to_owned()
            } else {
                m.iter()
                    .map(|(k, n)| format!("{k} ({n})"))
                    .collect::<Vec<_>>()
                    .join(", ")
            }
        };
        let format = serde_json::to_value(self.format)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default();
        println!("dataset       {}", path.display());
        println!("format        {format}");
        println!("cameras       {}", self.cameras);
        println!("images        {} files", self.images);
        println!("registered    {}", self.registered);
        let splits: Vec<String> = self
            .splits
            .iter()
            .map(|(k, n)| format!("{k} {n}"))
            .collect();
        println!("splits        {}", splits.join(", "));
        println!("points        {}", self.points);
        println!("resolutions   {}", list(&self.resolutions));
        println!("camera models {}", list(&self.camera_models));
        println!("undistorted   {} views (on load)", self.distorted);
        println!("masks         {}", list(&self.masks));
        println!("ignore masks  {} views", self.ignore_masks);
        if self.warnings.is_empty() {
            println!("warnings      none");
        } else {
            println!("warnings      {}", self.warnings.len());
            for w in &self.warnings {
                println!("  - {w}");
            }
        }
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let dataset = Dataset::open(&args.path, &OpenOptions::default())
        .with_context(|| format!("inspecting {}", args.path.display()))?;
    let report = Report::new(&dataset);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        report.print_text(&args.path);
    }
    Ok(())
}
