//! `damage-twin render MODEL.ply DATASET --view NAME --out FILE.png`: renders a model from one of
//! the dataset's cameras at a scale and saves the PNG, optionally with the damage layer over it
//! and the rendered damage masks beside it. Rendering and read-back are `damage::display`.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::bail;

use damage_twin::damage::Palette;
use damage_twin::damage::display::{DisplayStyle, RenderRequest, render_job};
use damage_twin::damage::evaluate::DamageReadout;
use damage_twin::damage::layer::DamageLayer;
use damage_twin::train::job::JobOptions;

use super::args::{ImageArgs, drive, open_dataset, read_model};

#[derive(clap::Args, Debug)]
pub struct Args {
    pub model: PathBuf,
    pub dataset: PathBuf,
    /// View name (image stem, e.g. `0049` or `r_8`).
    #[arg(long)]
    pub view: String,
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub images: ImageArgs,
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
    let splats = Arc::new(read_model(&args.model)?);
    let dataset = open_dataset(&args.dataset, args.images.background)?;
    let Some(index) = dataset.view_index(&args.view) else {
        bail!(
            "no view named {:?} in {} (views are named like {})",
            args.view,
            args.dataset.display(),
            dataset.example_view_names()
        );
    };
    let view = &dataset.views[index];
    let k = &view.camera.intrinsics;
    let (w, h) = args.images.scale.apply(k.width, k.height);
    let style = DisplayStyle {
        background: args.images.background,
        splat_scale: 1.0,
        damage: DamageLayer {
            enabled: args.damage_layer || args.damage_only,
            opacity: args.damage_opacity.clamp(0.0, 1.0),
            damage_only: args.damage_only,
            ..DamageLayer::default()
        },
    };
    if style.damage.enabled && splats.label_channels == 0 {
        eprintln!(
            "warning: {} has no label channels (not trained in label mode): no damage layer",
            args.model.display()
        );
    }
    let request = RenderRequest {
        camera: view.camera.resized(w, h),
        style,
        out: args.out.clone(),
        masks: args
            .masks
            .then(|| DamageReadout::for_model(&splats, Palette::default())),
    };
    let still = drive(
        render_job(splats, request.clone(), JobOptions::headless(None)),
        "rendering",
        true,
        |_| {},
    )?;
    for mask in &still.masks {
        println!(
            "wrote {} ({} {} pixels, {} mode)",
            mask.path.display(),
            mask.pixels,
            mask.class,
            request.masks.map(|r| r.mode).unwrap_or_default()
        );
    }
    println!(
        "wrote {} ({}x{}) from view {}",
        still.path.display(),
        still.width,
        still.height,
        view.name
    );
    Ok(())
}
