//! Shared by the frame-equivalence tests (`focused_frames`, `pixel_mask`): one small odd-sized
//! view (150×97, tiles cut at the right and bottom edges), a seeded model with label channels
//! that every camera looking at the origin's z = 7 sees, and bit patterns for exact comparisons.
#![allow(dead_code)]

use damage_twin::raster::{PixelGrads, Rasterizer, RenderOutput, RenderSettings, SplatGrads};
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use damage_twin::splats::random::random_in_view;
use glam::Vec3;

pub const W: u32 = 150;
pub const H: u32 = 97;

/// A W×H camera at `eye` looking at (0, 0, 7).
pub fn camera(eye: Vec3) -> Camera {
    let k = Intrinsics {
        width: W,
        height: H,
        fx: 140.0,
        fy: 138.0,
        cx: 74.3,
        cy: 49.1,
    };
    Camera::look_at(k, eye, Vec3::new(0.0, 0.0, 7.0), Vec3::NEG_Y)
}

/// `n` seeded Gaussians in the view of `camera(Vec3::ZERO)`, with `labels` label channels.
pub fn labelled_model(n: usize, seed: u64, labels: usize) -> Splats {
    let mut s = random_in_view(n, &camera(Vec3::ZERO), seed);
    let mut rng = fastrand::Rng::with_seed(seed + 1);
    s.label_channels = labels;
    s.raw_labels = (0..n * labels).map(|_| rng.f32() * 6.0 - 3.0).collect();
    s
}

pub fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// The backward of the frame `out` just rendered by `r`, with seeded pixel gradients (seed 11,
/// colour then label channels, drawn in order) at the pixels `inside` takes and zero elsewhere,
/// as a region loss's are.
pub fn seeded_backward(
    r: &mut Rasterizer,
    s: &Splats,
    cam: &Camera,
    settings: &RenderSettings,
    out: &RenderOutput,
    inside: impl Fn(usize) -> bool,
) -> SplatGrads {
    let pixels = out.color.len() / 3;
    let labels_per_pixel = out.labels.len().checked_div(pixels).unwrap_or(0);
    let mut rng = fastrand::Rng::with_seed(11);
    let mut draw = |pixel: usize| if inside(pixel) { rng.f32() - 0.5 } else { 0.0 };
    let v_color: Vec<f32> = (0..out.color.len()).map(|i| draw(i / 3)).collect();
    let v_labels: Vec<f32> = (0..out.labels.len())
        .map(|i| draw(i / labels_per_pixel))
        .collect();
    let v = PixelGrads {
        color: &v_color,
        alpha: None,
        depth: None,
        labels: Some(&v_labels),
    };
    let mut grads = SplatGrads::zeros(s);
    r.backward_pixels(s, cam, settings, &v, &mut grads);
    grads
}
