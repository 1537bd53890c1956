//! Each Gaussian's blending weight over chosen pixels of a view, `Σ_p w_p · α_ip T_ip`: how much
//! of those pixels it draws. The closed-form 2D→3D lift of FlashSplat (accumulate the weight over
//! damage and non-damage mask pixels, keep the majority) and each Gaussian's visibility in a view
//! both come from it, and so does each Gaussian's importance for a budget (`train::importance`).
//!
//! No kernel of its own: a label channel `D = Σ_i l_i α_i T_i` has `∂D/∂l_i = α_i T_i`, so the
//! rasterizer's exact backward with `v_labels = w` (and no colour gradient) leaves
//! `Σ_p w_p α_ip T_ip` in `ScreenGrads::v_labels` for every Gaussian, with the same culling,
//! tile order and early stop as the render.

use crate::raster::{PixelGrads, Rasterizer, RenderOutput, RenderSettings};
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

    fn scene() -> (Splats, Camera) {
        let mut splats = Splats::empty(0, 0);
        let mut rng = fastrand::Rng::with_seed(5);
        for id in 0..40 {
            let mean = Vec3::new(
                rng.f32() * 2.0 - 1.0,
                rng.f32() * 2.0 - 1.0,
                rng.f32() * 2.0,
            );
            splats.push(
                mean,
                Vec3::splat((0.05 + 0.1 * rng.f32()).ln()),
                Quat::IDENTITY,
                rng.f32() * 4.0 - 1.0,
                &[rng.f32(), rng.f32(), rng.f32()],
                &[],
                id,
                0,
            );
        }
        let k = Intrinsics {
            width: 48,
            height: 40,
            fx: 40.0,
            fy: 40.0,
            cx: 24.0,
            cy: 20.0,
        };
        (
            splats,
            Camera::new(k, Quat::IDENTITY, Vec3::new(0.0, 0.0, 4.0)),
        )
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
}
