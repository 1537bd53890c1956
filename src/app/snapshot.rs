//! A still of the current view for export: the model (as displayed: splat scale, damage layer)
//! rendered on the CPU reference renderer and written as a PNG. Runs on a worker thread; no
//! GPU read-back of the viewport.

use std::path::Path;

use anyhow::Context;

use crate::app::damage_layer;
use crate::app::files::write_atomically;
use crate::app::settings::Settings;
use crate::raster::{RenderSettings, render};
use crate::scene::{Camera, RgbImage};
use crate::splats::Splats;

/// Renders `splats` from `camera` as the viewer shows it.
pub fn render_view(splats: &Splats, camera: &Camera, settings: &Settings) -> RgbImage {
    let shown = damage_layer::display_splats(splats, settings.splat_scale, &settings.damage);
    let out = render(
        &shown,
        camera,
        &RenderSettings::new(glam::Vec3::from_array(settings.background), shown.sh_degree),
    );
    RgbImage {
        width: out.width,
        height: out.height,
        data: out.color,
    }
}

/// Renders and writes a PNG atomically.
pub fn render_png(
    path: &Path,
    splats: &Splats,
    camera: &Camera,
    settings: &Settings,
) -> anyhow::Result<()> {
    let image = render_view(splats, camera, settings);
    write_atomically(path, |tmp| {
        image
            .to_rgb8()
            .save_with_format(tmp, image::ImageFormat::Png)
            .with_context(|| format!("writing {}", path.display()))
    })
}
