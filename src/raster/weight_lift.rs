//! Each Gaussian's blending weight over chosen pixels of a view, `Σ_p w_p · α_ip T_ip`: how much
//! of those pixels it draws. The closed-form 2D→3D lift of FlashSplat (accumulate the weight over
//! damage and non-damage mask pixels, keep the majority) and each Gaussian's visibility in a view
//! both come from it, and so does each Gaussian's importance for a budget (`train::importance`).
//!
//! No kernel of its own: a label channel `D = Σ_i l_i α_i T_i` has `∂D/∂l_i = α_i T_i`, so the
//! rasterizer's exact backward with `v_labels = w` (and no colour gradient) leaves
//! `Σ_p w_p α_ip T_ip` in `ScreenGrads::v_labels` for every Gaussian, with the same culling,
//! tile order and early stop as the render.

use crate::raster::project::project;
use crate::raster::{
    CameraFrame, PixelGrads, Projected, Rasterizer, RenderOutput, RenderSettings, tile_grid,
    tile_rect,
};
use crate::scene::Camera;
use crate::splats::Splats;

/// Accumulates per-Gaussian weights over many views with one reusable rasterizer.
pub struct WeightLift {
    /// The model with exactly `channels` label channels (values unused: see the module docs).
    probe: Splats,
    channels: usize,
    rasterizer: Rasterizer,
    out: RenderOutput,
    v_color: Vec<f32>,
    v_labels: Vec<f32>,
    grads: crate::raster::SplatGrads,
    settings: RenderSettings,
    /// `view_of`'s projection, made before the render to choose its tiles.
    scout: Projected,
    /// `view_of`'s tiles (`ty * tiles_x + tx`).
    tiles: Vec<bool>,
}

impl WeightLift {
    /// A lift of `channels` pixel-weight maps per view (at most the label-channel limit).
    pub fn new(splats: &Splats, channels: usize, settings: RenderSettings) -> WeightLift {
        let mut probe = splats.clone();
        probe.label_channels = channels;
        probe.raw_labels = vec![0.0; splats.len() * channels];
        WeightLift {
            probe,
            channels,
            rasterizer: Rasterizer::new(),
            out: RenderOutput::default(),
            v_color: Vec::new(),
            v_labels: Vec::new(),
            grads: crate::raster::SplatGrads::default(),
            settings,
            scout: Projected::default(),
            tiles: Vec::new(),
        }
    }

    /// Renders `camera` and returns, per Gaussian `g` and map `k`, `Σ_p weight(p, k) · α T`
    /// at `[g * channels + k]`. `weight(pixel, k)` is asked once per pixel and map.
    pub fn view(&mut self, camera: &Camera, weight: impl Fn(usize, usize) -> f32) -> &[f32] {
        self.rasterizer
            .forward(&self.probe, camera, &self.settings, &mut self.out);
        let pixels = (self.out.width * self.out.height) as usize;
        self.v_color.clear();
        self.v_color.resize(pixels * 3, 0.0);
        self.v_labels.clear();
        self.v_labels.reserve(pixels * self.channels);
        for p in 0..pixels {
            for k in 0..self.channels {
                self.v_labels.push(weight(p, k));
            }
        }
        let v_out = PixelGrads {
            color: &self.v_color,
            alpha: None,
            depth: None,
            labels: Some(&self.v_labels),
        };
        self.rasterizer.backward_pixels(
            &self.probe,
            camera,
            &self.settings,
            &v_out,
            &mut self.grads,
        );
        &self.rasterizer.screen_grads().v_labels
    }

    /// [`WeightLift::view`] whose weights are only needed for the Gaussians `gaussians`: renders
    /// only the tiles they are binned into. Their weights are bit-identical to `view`'s (each
    /// tile blends its own depth-sorted list, and a Gaussian's weight sums its own tiles'
    /// intersections in tile order, so tiles it is not in change nothing of it); every other
    /// Gaussian's is that of the rendered tiles only. The hull drawing of a refinement needs
    /// the visibility of its few thousand selected Gaussians, not of the whole model.
    pub fn view_of(
        &mut self,
        camera: &Camera,
        gaussians: &[u32],
        weight: impl Fn(usize, usize) -> f32,
    ) -> &[f32] {
        let frame = CameraFrame::new(camera, &self.settings);
        project(&self.probe, &frame, &self.settings, &mut self.scout);
        let (width, height) = (frame.width, frame.height);
        let (tiles_x, tiles_y) = tile_grid(width, height);
        self.tiles.clear();
        self.tiles.resize((tiles_x * tiles_y) as usize, false);
        for &g in gaussians {
            let g = g as usize;
            let [x0, y0, x1, y1] = tile_rect(
                self.scout.means2d[g],
                self.scout.radii[g],
                self.scout.extents[g],
                width,
                height,
            );
            for ty in y0..y1 {
                let row = (ty * tiles_x) as usize;
                self.tiles[row + x0 as usize..row + x1 as usize].fill(true);
            }
        }
        self.rasterizer.set_active_tiles(Some(&self.tiles));
        self.view(camera, weight);
        self.rasterizer.set_active_tiles(None);
        &self.rasterizer.screen_grads().v_labels
    }

    /// The last view's projection (2D means, conics, radii per Gaussian).
    pub fn projected(&self) -> &crate::raster::Projected {
        self.rasterizer.projected()
    }

    /// The last view's forward (colour, alpha, depth; labels are meaningless).
    pub fn render(&self) -> &RenderOutput {
        &self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::reference;
    use crate::scene::Intrinsics;
    use glam::{Quat, Vec3};

    /// `count` Gaussians of random colour and opacity, centres uniform in ±`half.x` × ±`half.y`
    /// × [0, 2), sizes uniform in `size` (metres), seen by a `width`×`height` camera of focal
    /// `focal` at z = 4 looking down the axis.
    fn scattered(
        seed: u64,
        count: u64,
        half: glam::Vec2,
        size: std::ops::Range<f32>,
        (width, height, focal): (u32, u32, f32),
    ) -> (Splats, Camera) {
        let mut splats = Splats::empty(0, 0);
        let mut rng = fastrand::Rng::with_seed(seed);
        for id in 0..count {
            let mean = Vec3::new(
                rng.f32() * 2.0 * half.x - half.x,
                rng.f32() * 2.0 * half.y - half.y,
                rng.f32() * 2.0,
            );
            splats.push(
                mean,
                Vec3::splat((size.start + (size.end - size.start) * rng.f32()).ln()),
                Quat::IDENTITY,
                rng.f32() * 4.0 - 1.0,
                &[rng.f32(), rng.f32(), rng.f32()],
                &[],
                id,
                0,
            );
        }
        let k = Intrinsics {
            width,
            height,
            fx: focal,
            fy: focal,
            cx: width as f32 / 2.0,
            cy: height as f32 / 2.0,
        };
        (
            splats,
            Camera::new(k, Quat::IDENTITY, Vec3::new(0.0, 0.0, 4.0)),
        )
    }

    fn scene() -> (Splats, Camera) {
        scattered(5, 40, glam::Vec2::new(1.0, 1.0), 0.05..0.15, (48, 40, 40.0))
    }

    #[test]
    fn weights_match_the_reference_blend_sums() {
        let (splats, camera) = scene();
        let settings = RenderSettings::default();
        let mut lift = WeightLift::new(&splats, 2, settings);
        // Map 0: every pixel; map 1: the left half only.
        let w = 48;
        let weights = lift
            .view(
                &camera,
                |p, k| if k == 0 || p % w < w / 2 { 1.0 } else { 0.0 },
            )
            .to_vec();
        // The same sums straight from the reference: d(Σ_p w_p D_p)/d(label_g) by its backward.
        let mut probe = splats.clone();
        probe.label_channels = 2;
        probe.raw_labels = vec![0.0; splats.len() * 2];
        let (out, _) = reference::render(&probe, &camera, &settings);
        let pixels = (out.width * out.height) as usize;
        let v_labels: Vec<f32> = (0..pixels)
            .flat_map(|p| [1.0, if p % w < w / 2 { 1.0 } else { 0.0 }])
            .collect();
        let v_color = vec![0.0; pixels * 3];
        let (_, screen) = reference::backward(
            &probe,
            &camera,
            &settings,
            &PixelGrads {
                color: &v_color,
                alpha: None,
                depth: None,
                labels: Some(&v_labels),
            },
        );
        let scale = screen.v_labels.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(scale > 1.0, "the scene draws something");
        for (a, b) in weights.iter().zip(&screen.v_labels) {
            // Measured 4e-6 of the largest weight (f32 sums in another order).
            assert!((a - b).abs() <= 1e-4 * scale, "{a} vs {b}");
        }
        // The half map never exceeds the whole.
        for g in 0..splats.len() {
            assert!(weights[g * 2 + 1] <= weights[g * 2] + 1e-4 * scale);
        }
    }

    /// 400 small Gaussians scattered over a 160×128 image (10 × 8 tiles), some behind others.
    fn wide_scene() -> (Splats, Camera) {
        scattered(
            11,
            400,
            glam::Vec2::new(2.0, 1.6),
            0.02..0.08,
            (160, 128, 140.0),
        )
    }

    #[test]
    fn weights_of_a_subset_are_those_of_the_whole_render_bit_for_bit() {
        let (splats, camera) = wide_scene();
        let settings = RenderSettings::default();
        // A weight that differs per pixel, so that a pixel's share cannot hide.
        let weight = |p: usize, _: usize| 0.25 + (p % 7) as f32 * 0.125;
        let whole = WeightLift::new(&splats, 1, settings)
            .view(&camera, weight)
            .to_vec();
        // The left third of the scene, and a few scattered others.
        let subset: Vec<u32> = (0..splats.len() as u32)
            .filter(|&g| splats.means[g as usize].x < -0.7 || g % 37 == 0)
            .collect();
        let mut lift = WeightLift::new(&splats, 1, settings);
        let of_subset = lift.view_of(&camera, &subset, weight).to_vec();
        let skipped = lift.tiles.iter().filter(|&&t| !t).count();
        assert!(skipped > 10, "only {skipped} of 80 tiles skipped");
        let mut seen = 0;
        for &g in &subset {
            let g = g as usize;
            assert_eq!(
                of_subset[g].to_bits(),
                whole[g].to_bits(),
                "Gaussian {g}: {} against the whole render's {}",
                of_subset[g],
                whole[g]
            );
            seen += usize::from(whole[g] > 0.1);
        }
        assert!(seen > 20, "only {seen} of the subset draw anything");
        // The lift is reusable: a whole view after it is the whole render again.
        let again = lift.view(&camera, weight).to_vec();
        assert!(
            again
                .iter()
                .zip(&whole)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
    }
}
