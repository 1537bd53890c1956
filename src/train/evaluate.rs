//! Image quality of a model over views: the held-out PSNR and SSIM that training reports and
//! `eval` prints, and the NeRF-W half-photo PSNR. Renders with the CPU rasterizer; reads no
//! files.

use glam::Vec3;
use serde::Serialize;

use crate::metrics::{psnr, psnr_masked, ssim, ssim_masked};
use crate::raster::{RasterBackend, Rasterizer, RenderOutput, RenderSettings};
use crate::scene::RgbImage;
use crate::splats::Splats;
use crate::train::light_fit::fit_transform;
use crate::train::spec::TrainView;

/// Held-out image quality.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct EvalScores {
    /// Mean PSNR over views, dB.
    pub psnr: f64,
    pub ssim: f64,
    pub views: usize,
}

/// PSNR and SSIM of a render of `view` against its photo, over the pixels its region (the
/// ignore mask) uses: pedestrians and cars masked out of training are not scored either.
pub fn view_quality(rendered: &[f32], view: &TrainView) -> (f64, f64) {
    let (w, h) = (view.image.width, view.image.height);
    match &view.region {
        Some(used) => (
            psnr_masked(rendered, &view.image.data, &used.data),
            ssim_masked(rendered, &view.image.data, w, h, &used.data),
        ),
        None => (
            psnr(rendered, &view.image.data),
            ssim(rendered, &view.image.data, w, h),
        ),
    }
}

/// The NeRF-W protocol for a model whose photos differ in exposure: the photo's light (a gain
/// and offset per channel, `light_fit::fit_transform`) is fitted to the render on the left half
/// of the view, applied to the render, and PSNR is taken over the right half (pixels the view's
/// region uses only).
pub fn half_lit_psnr(rendered: &[f32], view: &TrainView) -> f64 {
    let (w, h) = (view.image.width as usize, view.image.height as usize);
    let used = |p: usize| view.region.as_ref().is_none_or(|m| m.data[p] != 0);
    let light = fit_transform(rendered, &view.image.data, &|p| p % w < w / 2 && used(p));
    let mut lit = RgbImage {
        width: view.image.width,
        height: view.image.height,
        data: rendered.to_vec(),
    };
    light.apply(&mut lit);
    let right: Vec<u8> = (0..w * h)
        .map(|p| u8::from(p % w >= w / 2 && used(p)))
        .collect();
    psnr_masked(&lit.data, &view.image.data, &right)
}

/// Renders every view and averages PSNR and SSIM.
pub(crate) fn evaluate_with(
    rasterizer: &mut dyn RasterBackend,
    out: &mut RenderOutput,
    splats: &Splats,
    views: &[TrainView],
    settings: &RenderSettings,
) -> EvalScores {
    let mut scores = EvalScores::default();
    for view in views {
        rasterizer.forward(splats, &view.camera, settings, out);
        let (p, s) = view_quality(&out.color, view);
        scores.psnr += p;
        scores.ssim += s;
    }
    let n = views.len().max(1) as f64;
    scores.psnr /= n;
    scores.ssim /= n;
    scores.views = views.len();
    scores
}

/// Mean PSNR and SSIM of a model over views (None when there are no views).
pub fn evaluate_views(
    splats: &Splats,
    views: &[TrainView],
    background: Vec3,
    sh_degree: u32,
) -> Option<EvalScores> {
    if views.is_empty() {
        return None;
    }
    let settings = RenderSettings::new(background, sh_degree.min(splats.sh_degree));
    let mut rasterizer = Rasterizer::new();
    let mut out = RenderOutput::default();
    Some(evaluate_with(
        &mut rasterizer as &mut dyn RasterBackend,
        &mut out,
        splats,
        views,
        &settings,
    ))
}
