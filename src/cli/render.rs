//! `damage-twin render MODEL.ply DATASET --view NAME --out FILE.png`: renders a model from one of
//! the dataset's cameras at a scale and saves the PNG. Rendering lives in `raster`.

use std::path::PathBuf;

use anyhow::{Context, bail};
use glam::Vec3;

use damage_twin::raster::{RenderSettings, render};
use damage_twin::scene::{ImageScale, RgbImage};

use super::train::{open_dataset, parse_background, parse_scale};

#[derive(clap::Args, Debug)]
pub struct Args {
    pub model: PathBuf,
    pub dataset: PathBuf,
    /// View name (image stem, e.g. `0049` or `r_8`).
    #[arg(long)]
    pub view: String,
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, default_value = "1", value_parser = parse_scale)]
    pub scale: ImageScale,
    #[arg(long, default_value = "black", value_parser = parse_background)]
    pub background: Vec3,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let splats = damage_twin::scene::ply::read_splats(&args.model)
        .with_context(|| format!("reading model {}", args.model.display()))?;
    let dataset = open_dataset(&args.dataset, args.background)?;
    let wanted = &args.view;
    let Some(view) = dataset
        .views
        .iter()
        .find(|v| &v.name == wanted || v.name.ends_with(&format!("/{wanted}")))
    else {
        let names: Vec<&str> = dataset
            .views
            .iter()
            .take(5)
            .map(|v| v.name.as_str())
            .collect();
        bail!(
            "no view named {wanted:?} in {} (e.g. {names:?})",
            args.dataset.display()
        );
    };
    let k = &view.camera.intrinsics;
    let (w, h) = args.scale.apply(k.width, k.height);
    let camera = view.camera.resized(w, h);
    let settings = RenderSettings::new(args.background, splats.sh_degree);
    let out = render(&splats, &camera, &settings);
    let image = RgbImage {
        width: out.width,
        height: out.height,
        data: out.color,
    };
    damage_twin::scene::load::save_png(&args.out, &image)
        .with_context(|| format!("writing {}", args.out.display()))?;
    println!(
        "wrote {} ({}x{}) from view {}",
        args.out.display(),
        w,
        h,
        view.name
    );
    Ok(())
}
