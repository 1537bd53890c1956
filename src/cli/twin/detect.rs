//! `damage-twin twin detect DIR --survey NAME [--json]`: the twin as of the survey before NAME,
//! rendered at NAME's poses, against NAME's masks: change maps (`surveys/NAME/changes/<view>.png`:
//! old damage in its class colour, new damage in the new-damage colour, damage no longer seen in
//! cyan) and `changes.json`, with precision and recall against `truth/new-damage` where present.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;
use serde::Serialize;

use damage_twin::damage::evaluate::DamageReadout;
use damage_twin::damage::{DamageClass, Palette};
use damage_twin::raster::RenderSettings;
use damage_twin::scene::ImageScale;
use damage_twin::timeline::changes::{
    DetectConfig, OLD_DAMAGE_THRESHOLD, StepScores, change_picture, detect,
};
use damage_twin::timeline::earlier::EarlierSurvey;

use crate::cli::args::parse_scale;

#[derive(clap::Args, Debug)]
pub struct Args {
    pub dir: PathBuf,
    #[arg(long)]
    pub survey: String,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    /// The resolution changes are found at (2: 480×270 of a 960×540 survey).
    #[arg(long, default_value = "2", value_parser = parse_scale)]
    pub scale: ImageScale,
    /// Old damage grown by this many pixels is not new (misregistration, blur).
    #[arg(long, default_value_t = 0)]
    pub band: u32,
    /// New-damage blobs smaller than this are dropped (pixels at the detection scale).
    #[arg(long, default_value_t = 0)]
    pub min_area: usize,
    /// Also drop candidates the earlier survey's own masks show at the same surface point
    /// (off by default: on the demo it removes growth next to old damage, docs/TIMELINE.md).
    #[arg(long)]
    pub earlier: bool,
    /// Earlier-survey check: mask pixels within this distance (pixels at the detection scale)
    /// of a candidate's surface point count as the earlier survey showing it.
    #[arg(long, default_value_t = 2)]
    pub earlier_radius: u32,
    /// Add the vote in 3D over the twin's Gaussians (off by default: on a coarse twin it drops
    /// thin new damage, docs/TIMELINE.md).
    #[arg(long)]
    pub vote: bool,
    /// Label mode: the class probability above which the twin's render is old damage.
    #[arg(long, default_value_t = OLD_DAMAGE_THRESHOLD)]
    pub old_threshold: f32,
}

#[derive(Serialize)]
struct ClassFigures {
    pixels: u64,
    truth_pixels: Option<u64>,
    precision: Option<f64>,
    recall: Option<f64>,
    f1: Option<f64>,
    iou: Option<f64>,
}

#[derive(Serialize)]
struct Summary<'a> {
    survey: &'a str,
    twin_of: &'a str,
    scale: ImageScale,
    views: usize,
    new_damage: BTreeMap<String, ClassFigures>,
    /// The same figures after each cleaning step: raw, band, area, earlier, vote.
    steps: &'a [StepScores],
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut twin = super::open(&args.dir)?;
    let index = twin.survey_index(&args.survey)?;
    let previous = twin.project.surveys[..index]
        .iter()
        .rev()
        .find(|s| s.model.is_some())
        .map(|s| s.name.clone())
        .with_context(|| {
            format!(
                "no survey before {} has a model to compare with",
                args.survey
            )
        })?;
    let model = twin.load_model(&previous)?.context("the previous model")?;
    let dataset = twin.open_survey_dataset(&args.survey)?;
    let palette = Palette {
        colours: DamageClass::ALL.map(|c| twin.project.colour(c)),
    };
    let config = DetectConfig {
        scale: args.scale,
        readout: DamageReadout::for_model(&model, palette),
        background: glam::Vec3::from_array(twin.project.settings.background),
        band_px: args.band,
        min_area_px: args.min_area,
        vote: args.vote,
        old_threshold: args.old_threshold,
    };
    let earlier = if !args.earlier {
        None
    } else {
        let settings = RenderSettings::new(config.background, model.sh_degree);
        let earlier_dataset = twin.open_survey_dataset(&previous)?;
        Some(EarlierSurvey::load(
            &model,
            &earlier_dataset,
            args.scale,
            &settings,
            args.earlier_radius,
        )?)
    };
    let detection = detect(&model, &dataset, &config, earlier.as_ref(), &mut |_, _| {})?;
    let folder = twin.survey_dir(&args.survey).join("changes");
    std::fs::create_dir_all(&folder).with_context(|| format!("creating {}", folder.display()))?;
    for view in &detection.views {
        let photo = dataset.load_view(view.index, args.scale)?;
        let picture = change_picture(
            view,
            &photo.image,
            &palette.colours,
            twin.project.settings.new_damage_colour,
        );
        let path = folder.join(format!("{}.png", view.name.replace('/', "_")));
        damage_twin::damage::display::save_png(&path, &picture)?;
    }
    let last = detection.summary().cloned().unwrap_or_default();
    let new_damage = last
        .pixels
        .iter()
        .map(|(class, &pixels)| {
            (
                class.clone(),
                ClassFigures {
                    pixels,
                    truth_pixels: last.truth_pixels.get(class).copied(),
                    precision: last.precision.get(class).copied(),
                    recall: last.recall.get(class).copied(),
                    f1: last.f1.get(class).copied(),
                    iou: last.iou.get(class).copied(),
                },
            )
        })
        .collect();
    let summary = Summary {
        survey: &args.survey,
        twin_of: &previous,
        scale: args.scale,
        views: detection.views.len(),
        new_damage,
        steps: &detection.steps,
    };
    let json = serde_json::to_string_pretty(&summary)?;
    let path = folder.join("changes.json");
    damage_twin::scene::atomic::write_atomic(&path, |w| {
        std::io::Write::write_all(w, json.as_bytes())
    })
    .with_context(|| format!("writing {}", path.display()))?;
    let relative = twin.relative(&folder);
    twin.project.surveys[index].changes = Some(relative);
    twin.save()?;
    if args.json {
        println!("{json}");
    } else {
        println!(
            "{} views of {} against the twin of {}; change maps in {}",
            summary.views,
            args.survey,
            previous,
            folder.display()
        );
        for (class, f) in &summary.new_damage {
            let truth = match (f.precision, f.recall, f.iou) {
                (Some(p), Some(r), Some(i)) => {
                    format!("  precision {p:.3}  recall {r:.3}  IoU {i:.3}")
                }
                _ => String::new(),
            };
            println!("  new {class:<9} {:>8} px{truth}", f.pixels);
        }
    }
    Ok(())
}
