//! A still of the twin as the viewer shows it (splat scale, damage layer, background), rendered
//! on the CPU renderer and written as a PNG: the viewer's "export view", `render` and the demo's
//! renders all go through here, so a file shows what the screen shows.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::Vec3;

use crate::damage::evaluate::{DamageReadout, predicted_masks};
use crate::damage::layer::{DamageLayer, display_splats};
use crate::raster::{RenderSettings, render};
use crate::scene::atomic::write_atomic;
use crate::scene::load::save_mask_png;
use crate::scene::{Camera, DamageClass, Mask, RgbImage, SceneError};
use crate::splats::Splats;
use crate::train::job::{Job, JobOptions};

/// How a still is drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct DisplayStyle {
    /// Linear RGB in [0, 1].
    pub background: Vec3,
    /// Multiplier on every Gaussian's scale (1 = as trained).
    pub splat_scale: f32,
    pub damage: DamageLayer,
}

impl Default for DisplayStyle {
    fn default() -> Self {
        DisplayStyle {
            background: Vec3::ZERO,
            splat_scale: 1.0,
            damage: DamageLayer::default(),
        }
    }
}

/// Renders `splats` from `camera` as the viewer shows it.
pub fn render_view(splats: &Splats, camera: &Camera, style: &DisplayStyle) -> RgbImage {
    let shown = display_splats(splats, style.splat_scale, &style.damage);
    let out = render(
        &shown,
        camera,
        &RenderSettings::new(style.background, shown.sh_degree),
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
    style: &DisplayStyle,
) -> Result<(), SceneError> {
    let image = render_view(splats, camera, style);
    save_png(path, &image)
}

/// Writes an RGB image as a PNG atomically (temporary file, fsync, rename).
pub fn save_png(path: &Path, image: &RgbImage) -> Result<(), SceneError> {
    let bytes = png_bytes(image)
        .map_err(|e| SceneError::invalid(path, format!("encoding the PNG: {e}")))?;
    write_atomic(path, |w| std::io::Write::write_all(w, &bytes))
}

/// An RGB image encoded as PNG in memory.
pub fn png_bytes(image: &RgbImage) -> Result<Vec<u8>, image::ImageError> {
    let mut bytes = Vec::new();
    image.to_rgb8().write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )?;
    Ok(bytes)
}

/// A still to render and write, with optionally the rendered damage masks beside it.
#[derive(Clone, Debug)]
pub struct RenderRequest {
    pub camera: Camera,
    pub style: DisplayStyle,
    pub out: PathBuf,
    /// Also write `<stem>_<class>.png` beside `out`, read back this way.
    pub masks: Option<DamageReadout>,
}

/// One damage mask written beside a still.
#[derive(Clone, Debug, PartialEq)]
pub struct WrittenMask {
    pub class: DamageClass,
    pub path: PathBuf,
    /// Damage pixels in it.
    pub pixels: usize,
}

/// What a render wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderedStill {
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
    pub masks: Vec<WrittenMask>,
}

/// Renders the still as displayed and, when asked, the damage masks (from the plain render:
/// the damage layer must not colour what is read back).
pub fn render_still(splats: &Splats, request: &RenderRequest) -> Result<RenderedStill, SceneError> {
    render_png(&request.out, splats, &request.camera, &request.style)?;
    let mut masks = Vec::new();
    if let Some(readout) = &request.masks {
        let rendered = rendered_masks(splats, &request.camera, readout, request.style.background);
        let stem = request
            .out
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "render".into());
        for (&class, mask) in DamageClass::ALL.iter().zip(rendered) {
            let path = request.out.with_file_name(format!("{stem}_{class}.png"));
            save_mask_png(&path, &mask)?;
            masks.push(WrittenMask {
                class,
                path,
                pixels: mask.data.iter().filter(|&&v| v != 0).count(),
            });
        }
    }
    Ok(RenderedStill {
        path: request.out.clone(),
        width: request.camera.intrinsics.width,
        height: request.camera.intrinsics.height,
        masks,
    })
}

/// The twin's damage masks seen from `camera` (per class in `DamageClass::ALL` order), read
/// from a plain render (no damage layer, which would colour what is read back) as `readout`
/// says: what `render --masks` writes and `masks export` hands to annotation tools.
pub fn rendered_masks(
    splats: &Splats,
    camera: &Camera,
    readout: &DamageReadout,
    background: Vec3,
) -> Vec<Mask> {
    let (splats, readout) = readout.prepare(splats);
    let out = render(
        &splats,
        camera,
        &RenderSettings::new(background, splats.sh_degree),
    );
    predicted_masks(&out, &readout)
}

/// `render_still` as a job.
pub fn render_job(
    splats: Arc<Splats>,
    request: RenderRequest,
    options: JobOptions,
) -> Job<RenderedStill> {
    Job::spawn("render", options, move |_| {
        Ok(render_still(&splats, &request)?)
    })
}
