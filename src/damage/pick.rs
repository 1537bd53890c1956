//! What a person points at, from the render: the Gaussian drawing most of a clicked pixel (the
//! blending weight `α·T` of `lift`), the surface point there (the render's expected depth), the
//! Gaussians inside a screen shape that are not behind the surface shown (front-most
//! selection), and a view's 2D mask lifted to its Gaussians by majority of weight. Each renders
//! only the window of the image it needs, so a click costs a few dozen pixels.

use glam::{Vec2, Vec3};

use crate::raster::RenderSettings;
use crate::raster::weight_lift::WeightLift;
use crate::scene::{Camera, Intrinsics, Mask};
use crate::splats::Splats;
use crate::splats::model::state::{DELETED, HIDDEN};
use crate::splats::selection::Shape;

/// Side of the window rendered around a clicked pixel.
const CLICK_WINDOW: u32 = 9;
/// Longest side of the window rendered for a shape (larger shapes render at a coarser scale).
const SHAPE_WINDOW_MAX: u32 = 512;
/// A Gaussian takes part in a mask's vote when it draws at least this many pixels' worth of
/// weight in the view.
pub const MIN_WEIGHT: f32 = 0.25;

/// A part of `camera`'s image rendered on its own: pixels `[min, max)` of the original, scaled
/// by `scale`.
struct Window {
    camera: Camera,
    min: Vec2,
    scale: f32,
}

impl Window {
    fn new(camera: &Camera, min: Vec2, max: Vec2, max_side: u32) -> Option<Window> {
        let k = camera.intrinsics;
        let (w, h) = (k.width as f32, k.height as f32);
        let min = min.max(Vec2::ZERO).floor();
        let max = max.min(Vec2::new(w, h)).ceil();
        let size = max - min;
        if !(size.x >= 1.0 && size.y >= 1.0) {
            return None;
        }
        let scale = (max_side as f32 / size.x.max(size.y)).min(1.0);
        let width = ((size.x * scale).round() as u32).max(1);
        let height = ((size.y * scale).round() as u32).max(1);
        let intrinsics = Intrinsics {
            width,
            height,
            fx: k.fx * scale,
            fy: k.fy * scale,
            cx: (k.cx - min.x) * scale,
            cy: (k.cy - min.y) * scale,
        };
        Some(Window {
            camera: Camera {
                intrinsics,
                ..*camera
            },
            min,
            scale,
        })
    }
}

/// The model as drawn: hidden and deleted Gaussians neither draw nor occlude.
fn drawn(splats: &Splats) -> Splats {
    let mut probe = splats.clone();
    for (opacity, &bits) in probe.raw_opacities.iter_mut().zip(&splats.meta.state) {
        if bits & (HIDDEN | DELETED) != 0 {
            *opacity = -30.0;
        }
    }
    probe
}

fn weights_in(
    splats: &Splats,
    window: &Window,
    settings: &RenderSettings,
    weight: impl Fn(usize) -> f32,
) -> Vec<f32> {
    let mut lift = WeightLift::new(&drawn(splats), 1, *settings);
    lift.view(&window.camera, |p, _| weight(p)).to_vec()
}

/// The Gaussian drawing most of pixel `pixel` of `camera` (by `α·T`), if any draws there.
pub fn pick(
    splats: &Splats,
    camera: &Camera,
    pixel: Vec2,
    settings: &RenderSettings,
) -> Option<usize> {
    let half = Vec2::splat(CLICK_WINDOW as f32 / 2.0);
    let window = Window::new(camera, pixel - half, pixel + half, CLICK_WINDOW)?;
    let centre = window.camera.intrinsics.width as usize * (CLICK_WINDOW as usize / 2)
        + CLICK_WINDOW as usize / 2;
    let weights = weights_in(splats, &window, settings, |p| {
        f32::from(u8::from(p == centre))
    });
    weights
        .iter()
        .enumerate()
        .filter(|&(_, &w)| w > 1e-4)
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(g, _)| g)
}

/// The surface point seen at pixel `pixel` of `camera`: along the pixel's ray at the render's
/// expected depth (`Σ z α T / Σ α T`), when the model covers the pixel at least half.
pub fn surface_point(
    splats: &Splats,
    camera: &Camera,
    pixel: Vec2,
    settings: &RenderSettings,
) -> Option<Vec3> {
    let half = Vec2::ONE;
    let window = Window::new(camera, pixel - half, pixel + half, 2)?;
    let out = crate::raster::render(&drawn(splats), &window.camera, settings);
    let w = window.camera.intrinsics.width as usize;
    let local = ((pixel - window.min) * window.scale).floor();
    let p = (local.y as usize).min(out.height as usize - 1) * w + (local.x as usize).min(w - 1);
    let alpha = *out.alpha.get(p)?;
    if !(alpha > 0.5) {
        return None;
    }
    let z = out.depth[p] / alpha;
    Some(unproject(camera, pixel, z))
}

/// The world point at camera depth `z` on the ray through `pixel` (image coordinates).
pub fn unproject(camera: &Camera, pixel: Vec2, z: f32) -> Vec3 {
    let k = camera.intrinsics;
    let local = Vec3::new((pixel.x - k.cx) / k.fx * z, (pixel.y - k.cy) / k.fy * z, z);
    camera.rotation.inverse() * (local - camera.translation)
}

/// Per Gaussian: its centre projects inside the screen `shape` and is not behind the surface
/// the render shows there (front-most selection, a depth test against the render's expected
/// depth with a tolerance of the Gaussian's own size and 2 % of the depth). Volumes and empty
/// shapes hit nothing.
pub fn front_hits(
    splats: &Splats,
    camera: &Camera,
    shape: &Shape,
    settings: &RenderSettings,
) -> Vec<bool> {
    let mut hit = vec![false; splats.len()];
    let Some((min, max)) = shape.screen_bounds() else {
        return hit;
    };
    let Some(window) = Window::new(camera, min, max, SHAPE_WINDOW_MAX) else {
        return hit;
    };
    let out = crate::raster::render(&drawn(splats), &window.camera, settings);
    let (w, h) = (out.width as usize, out.height as usize);
    for (g, hit) in hit.iter_mut().enumerate() {
        if splats.meta.state[g] & (HIDDEN | DELETED) != 0 {
            continue;
        }
        let mean = splats.means[g];
        let Some(pixel) = camera.project(mean) else {
            continue;
        };
        if !shape.contains_pixel(pixel) {
            continue;
        }
        let local = ((pixel - window.min) * window.scale).floor();
        let (x, y) = (local.x as usize, local.y as usize);
        if local.x < 0.0 || local.y < 0.0 || x >= w || y >= h {
            continue;
        }
        let p = y * w + x;
        let z = (camera.rotation * mean + camera.translation).z;
        let surface = if out.alpha[p] > 0.5 {
            out.depth[p] / out.alpha[p]
        } else {
            f32::INFINITY
        };
        let size = splats.log_scales[g].max_element().exp();
        *hit = z <= surface + 2.0 * size + 0.02 * surface.min(z);
    }
    hit
}

/// A view's 2D mask lifted to the Gaussians: those whose weight over the mask's pixels exceeds
/// their weight over the rest of the view (the closed-form lift, majority vote), among those
/// that draw at least [`MIN_WEIGHT`] pixels there. The mask is at `camera`'s size.
pub fn mask_hits(
    splats: &Splats,
    camera: &Camera,
    mask: &Mask,
    settings: &RenderSettings,
) -> Vec<bool> {
    let k = camera.intrinsics;
    if (mask.width, mask.height) != (k.width, k.height) {
        return vec![false; splats.len()];
    }
    let mut lift = WeightLift::new(&drawn(splats), 2, *settings);
    let weights = lift.view(camera, |p, k| {
        let inside = mask.data.get(p).is_some_and(|&v| v != 0);
        f32::from(u8::from(inside == (k == 0)))
    });
    weights
        .chunks_exact(2)
        .map(|w| w[0] > w[1] && w[0] + w[1] >= MIN_WEIGHT)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    /// A red square of Gaussians at z = 0 in front of a blue one at z = 1 (the camera at
    /// z = -4 looking along +z).
    fn two_walls() -> (Splats, Camera) {
        let mut splats = Splats::empty(0, 0);
        let mut id = 0;
        for (z, colour) in [(0.0, [1.0, 0.0, 0.0]), (1.0, [0.0, 0.0, 1.0])] {
            for x in -4..=4 {
                for y in -4..=4 {
                    splats.push(
                        Vec3::new(x as f32 * 0.1, y as f32 * 0.1, z),
                        Vec3::splat(0.08f32.ln()),
                        Quat::IDENTITY,
                        6.0,
                        &colour,
                        &[],
                        id,
                        0,
                    );
                    id += 1;
                }
            }
        }
        let k = Intrinsics {
            width: 64,
            height: 48,
            fx: 60.0,
            fy: 60.0,
            cx: 32.0,
            cy: 24.0,
        };
        (
            splats,
            Camera::new(k, Quat::IDENTITY, Vec3::new(0.0, 0.0, 4.0)),
        )
    }

    #[test]
    fn a_click_picks_the_front_wall_and_its_surface() {
        let (splats, camera) = two_walls();
        let settings = RenderSettings::new(Vec3::ZERO, 0);
        let centre = Vec2::new(32.0, 24.0);
        let g = pick(&splats, &camera, centre, &settings).expect("picks");
        assert_eq!(splats.means[g].z, 0.0, "the front wall draws the pixel");
        assert!(
            splats.means[g].truncate().length() < 0.11,
            "{:?}",
            splats.means[g]
        );
        let point = surface_point(&splats, &camera, centre, &settings).expect("surface");
        assert!(
            point.z.abs() < 0.1 && point.truncate().length() < 0.05,
            "{point}"
        );
        assert_eq!(pick(&splats, &camera, Vec2::new(1.0, 1.0), &settings), None);
    }

    #[test]
    fn front_most_leaves_the_hidden_wall_out_and_sees_it_once_the_front_is_hidden() {
        let (mut splats, camera) = two_walls();
        let settings = RenderSettings::new(Vec3::ZERO, 0);
        let shape = Shape::Rect {
            a: Vec2::new(26.0, 18.0),
            b: Vec2::new(38.0, 30.0),
        };
        let hit = front_hits(&splats, &camera, &shape, &settings);
        let (front, back): (Vec<usize>, Vec<usize>) = (0..splats.len())
            .filter(|&g| hit[g])
            .partition(|&g| splats.means[g].z == 0.0);
        assert!(front.len() >= 4, "{front:?}");
        assert!(back.is_empty(), "{back:?}");
        // Straight through, the back wall's centres inside the rectangle count.
        let through = crate::splats::selection::hits(&splats, &camera, &shape);
        assert!((0..splats.len()).any(|g| through[g] && splats.means[g].z == 1.0));
        for g in 0..81 {
            splats.meta.state[g] |= HIDDEN;
        }
        let hit = front_hits(&splats, &camera, &shape, &settings);
        assert!((81..162).any(|g| hit[g]) && !(0..81).any(|g| hit[g]));
    }

    #[test]
    fn a_mask_lifts_to_the_gaussians_that_draw_it() {
        let (splats, camera) = two_walls();
        let settings = RenderSettings::new(Vec3::ZERO, 0);
        let k = camera.intrinsics;
        let mut mask = Mask::empty(k.width, k.height);
        // The left half of the front wall.
        for y in 0..k.height {
            for x in 0..32 {
                mask.data[(y * k.width + x) as usize] = 1;
            }
        }
        let hit = mask_hits(&splats, &camera, &mask, &settings);
        for (g, (&is_hit, mean)) in hit.iter().zip(&splats.means).take(81).enumerate() {
            if mean.x < -0.05 {
                assert!(is_hit, "left Gaussian {g} at {}", mean.x);
            } else if mean.x > 0.05 {
                assert!(!is_hit, "right Gaussian {g} at {}", mean.x);
            }
        }
        assert!(!(81..162).any(|g| hit[g]), "the hidden wall draws nothing");
    }
}
