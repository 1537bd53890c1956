//! `damage-twin render MODEL.ply DATASET --view NAME --out FILE.png`: renders a model from one of
//! the dataset's cameras at a scale and saves the PNG, optionally with the damage layer over it
//! and the rendered damage masks beside it. Rendering lives in `raster`, reading damage back in
//! `damage::evaluate`.

use std::path::PathBuf;

use anyhow::{Context, bail};
use glam::Vec3;

use damage_twin::app::settings::{DamageLayer, Settings};
use damage_twin::app::snapshot;
use damage_twin::damage::evaluate::{DamageReadout, predicted_masks};
use damage_twin::damage::{DamageClass, Palette};
use damage_twin::raster::{RenderSettings, render};
use damage_twin::scene::ImageScale;

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
    /// Draw the damage layer (class colours by label probability) over the photo-real render.
    #[arg(long)]
    pub damage_layer: bool,
    /// Opacity of the damage layer.
    #[arg(long, default_value_t = 0.7)]
    pub damage_opacity: f32,
    /// Damage layer over a dimmed grey render (damage only).
    #[arg(long)]
    pub damage_only: bool,
    /// Also write the rendered damage masks (label channels at 0.5, or overlay colours read
    /// back) as `<stem>_<class>.png` next to `--out`.
    #[arg(long)]
    pub masks: bool,
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
    let settings = Settings {
        background: args.background.to_array(),
        damage: DamageLayer {
            enabled: args.damage_layer || args.damage_only,
            opacity: args.damage_opacity.clamp(0.0, 1.0),
            damage_only: args.damage_only,
            ..DamageLayer::default()
        },
        ..Settings::default()
    };
    if settings.damage.enabled && splats.label_channels == 0 {
        eprintln!(
            "warning: {} has no label channels (not trained in label mode): no damage layer",
            args.model.display()
        );
    }
    snapshot::render_png(&args.out, &splats, &camera, &settings)
        .with_context(|| format!("writing {}", args.out.display()))?;
    if args.masks {
        let out = render(
            &splats,
            &camera,
            &RenderSettings::new(args.background, splats.sh_degree),
        );
        let readout = DamageReadout::for_model(&splats, Palette::default());
        let stem = args
            .out
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "render".into());
        for (class, mask) in DamageClass::ALL.iter().zip(predicted_masks(&out, &readout)) {
            let path = args.out.with_file_name(format!("{stem}_{class}.png"));
            damage_twin::scene::load::save_mask_png(&path, &mask)
                .with_context(|| format!("writing {}", path.display()))?;
            println!(
                "wrote {} ({} {} pixels, {} mode)",
                path.display(),
                mask.data.iter().filter(|&&v| v != 0).count(),
                class,
                readout.mode
            );
        }
    }
    println!(
        "wrote {} ({}x{}) from view {}",
        args.out.display(),
        w,
        h,
        view.name
    );
    Ok(())
}
