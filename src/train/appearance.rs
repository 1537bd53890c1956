//! Per-image appearance in training: each training photo's exposure and white balance as a gain
//! and an offset per channel applied to the render before the photometric loss, `c' = g ⊙ c + o`,
//! learnt with the model (Adam, a small rate, a weak pull towards the identity). The Gaussians
//! then hold the scene's colour and each photo's light lives in its own six numbers, instead of
//! the Gaussians averaging the exposures or baking them into view-dependent colour. A held-out
//! photo has no fitted transform: the NeRF-W protocol fits one on half of it and scores the other
//! half (`damage::assess`'s `half_appearance`, `eval --half-appearance`, docs/ROBUSTNESS.md). The
//! model is the timeline's between surveys (`timeline::appearance`), fitted in closed form by
//! `train::light_fit`, and the learnt transforms come out as the same `ColourTransform`.

use glam::Vec3;

use crate::scene::project::ColourTransform;

/// How the per-image transforms are learnt.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AppearanceConfig {
    /// Adam rate of the gains and offsets.
    pub lr: f32,
    /// Weight of `|g − 1|² + |o|²` added to the loss (keeps the average photo's light in the
    /// Gaussians rather than in the transforms).
    pub prior: f32,
    /// First training step that goes through the transforms. Before it the Gaussians are too
    /// rough for a photo's light to be told from the model's own error, and a transform learnt
    /// then absorbs that error instead.
    #[serde(default)]
    pub start_step: u32,
}

impl Default for AppearanceConfig {
    fn default() -> Self {
        AppearanceConfig {
            lr: 5e-3,
            prior: 1e-2,
            start_step: 0,
        }
    }
}

/// One photo's transform and its optimiser state.
#[derive(Clone, Debug)]
struct ViewTransform {
    /// `[g_r, g_g, g_b, o_r, o_g, o_b]`.
    params: [f32; 6],
    m: [f32; 6],
    v: [f32; 6],
    steps: i32,
}

impl Default for ViewTransform {
    fn default() -> Self {
        ViewTransform {
            params: [1.0, 1.0, 1.0, 0.0, 0.0, 0.0],
            m: [0.0; 6],
            v: [0.0; 6],
            steps: 0,
        }
    }
}

/// The transforms of every training view.
#[derive(Clone, Debug)]
pub struct AppearanceModel {
    config: AppearanceConfig,
    views: Vec<ViewTransform>,
}

impl AppearanceModel {
    pub fn new(views: usize, config: AppearanceConfig) -> AppearanceModel {
        AppearanceModel {
            config,
            views: vec![ViewTransform::default(); views],
        }
    }

    /// Whether step `step` goes through the transforms.
    pub fn active_at(&self, step: u32) -> bool {
        step >= self.config.start_step
    }

    /// View `view`'s gain and offset.
    pub fn transform(&self, view: usize) -> (Vec3, Vec3) {
        let p = self.views[view].params;
        (Vec3::new(p[0], p[1], p[2]), Vec3::new(p[3], p[4], p[5]))
    }

    /// Pins the transforms' mean to the identity and returns the mean that was taken out, per
    /// channel `(gain, offset)`, for the caller to fold into the Gaussians' colours
    /// (`fold_into_colours`): `g_v ⊙ c + o_v = g'_v ⊙ (ḡ ⊙ c + ō) + o'_v` with `g'_v = g_v / ḡ`,
    /// `o'_v = o_v − g'_v ⊙ ō`, so every photo's render is unchanged. Without it the transforms
    /// and the Gaussians share a free overall gain and offset, which the weak prior does not
    /// hold: the transforms drift together and the Gaussians' own colours end away from every
    /// photo's light (docs/ROBUSTNESS.md).
    pub fn recentre(&mut self) -> (Vec3, Vec3) {
        let n = self.views.len().max(1) as f32;
        let mut gain = [0.0f32; 3];
        let mut offset = [0.0f32; 3];
        for t in &self.views {
            for k in 0..3 {
                gain[k] += t.params[k] / n;
                offset[k] += t.params[3 + k] / n;
            }
        }
        if !gain.iter().chain(&offset).all(|v| v.is_finite()) || gain.iter().any(|&g| g <= 0.05) {
            return (Vec3::ONE, Vec3::ZERO);
        }
        for t in &mut self.views {
            for k in 0..3 {
                t.params[k] /= gain[k];
                t.params[3 + k] -= t.params[k] * offset[k];
            }
        }
        (Vec3::from(gain), Vec3::from(offset))
    }

    /// Every view's light as the timeline's colour transform (the same per-channel model the
    /// timeline fits between surveys), `photo ≈ transform(render)`.
    pub fn transforms(&self) -> Vec<ColourTransform> {
        self.views
            .iter()
            .map(|t| {
                let p = t.params;
                ColourTransform {
                    matrix: [[p[0], 0.0, 0.0], [0.0, p[1], 0.0], [0.0, 0.0, p[2]]],
                    offset: [p[3], p[4], p[5]],
                }
            })
            .collect()
    }

    /// `out = g ⊙ color + o` for view `view` (RGB interleaved).
    pub fn apply(&self, view: usize, color: &[f32], out: &mut Vec<f32>) {
        let p = self.views[view].params;
        out.clear();
        out.extend(
            color
                .chunks_exact(3)
                .flat_map(|c| [0, 1, 2].map(|k| p[k] * c[k] + p[3 + k])),
        );
    }

    /// Turns the loss gradient with respect to the transformed render (`v_color`, in place)
    /// into the gradient with respect to the render, and takes one Adam step on view `view`'s
    /// transform. Returns the prior's loss.
    pub fn backward_and_step(&mut self, view: usize, color: &[f32], v_color: &mut [f32]) -> f32 {
        let AppearanceConfig { lr, prior, .. } = self.config;
        let t = &mut self.views[view];
        let p = t.params;
        let mut grad = [0.0f64; 6];
        for (c, v) in color.chunks_exact(3).zip(v_color.chunks_exact_mut(3)) {
            for k in 0..3 {
                grad[k] += f64::from(v[k] * c[k]);
                grad[3 + k] += f64::from(v[k]);
                v[k] *= p[k];
            }
        }
        let mut prior_loss = 0.0;
        for (k, g) in grad.iter_mut().enumerate() {
            let deviation = if k < 3 { p[k] - 1.0 } else { p[k] };
            prior_loss += prior * deviation * deviation;
            *g += f64::from(2.0 * prior * deviation);
        }
        if !grad.iter().all(|g| g.is_finite()) {
            return prior_loss;
        }
        // Adam (β1 0.9, β2 0.999), bias-corrected by the view's own step count.
        t.steps += 1;
        let (b1, b2) = (0.9f32, 0.999f32);
        let correction1 = 1.0 - b1.powi(t.steps);
        let correction2 = 1.0 - b2.powi(t.steps);
        for (k, &g) in grad.iter().enumerate() {
            let g = g as f32;
            t.m[k] = b1 * t.m[k] + (1.0 - b1) * g;
            t.v[k] = b2 * t.v[k] + (1.0 - b2) * g * g;
            let step = lr * (t.m[k] / correction1) / ((t.v[k] / correction2).sqrt() + 1e-8);
            t.params[k] -= step;
        }
        prior_loss
    }
}

/// Replaces every Gaussian's colour `c` by `gain ⊙ c + offset`: the colour is `0.5 + Σ_k Y_k c_k`
/// (before its clamp at 0), so the DC coefficient takes the offset and every coefficient the gain.
pub fn fold_into_colours(splats: &mut crate::splats::Splats, gain: Vec3, offset: Vec3) {
    use crate::splats::model::SH_C0;
    let coeffs = splats.sh_coeffs();
    let (gain, offset) = (gain.to_array(), offset.to_array());
    for gaussian in splats.sh.chunks_exact_mut(coeffs * 3) {
        for (k, coefficient) in gaussian.chunks_exact_mut(3).enumerate() {
            for c in 0..3 {
                coefficient[c] *= gain[c];
                if k == 0 {
                    coefficient[c] += (0.5 * gain[c] + offset[c] - 0.5) / SH_C0;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recentring_keeps_every_photos_render_and_pins_the_mean() {
        use crate::splats::Splats;
        use glam::Quat;
        let mut model = AppearanceModel::new(2, AppearanceConfig::default());
        model.views[0].params = [0.8, 0.9, 1.1, 0.05, -0.02, 0.0];
        model.views[1].params = [0.6, 0.7, 0.9, 0.01, 0.03, 0.04];
        let mut splats = Splats::empty(1, 0);
        let sh: Vec<f32> = (0..12).map(|i| 0.05 * i as f32 - 0.2).collect();
        splats.push(Vec3::ZERO, Vec3::ZERO, Quat::IDENTITY, 0.0, &sh, &[], 1, 0);
        // A colour from the SH at one direction: 0.5 + Σ Y_k c_k per channel.
        let colour = |splats: &Splats| {
            let mut basis = [0.0f32; 16];
            crate::splats::sh::sh_basis(1, Vec3::new(0.3, -0.4, 0.87).normalize(), &mut basis);
            Vec3::from_array(std::array::from_fn(|c| {
                0.5 + (0..4).map(|k| basis[k] * splats.sh[k * 3 + c]).sum::<f32>()
            }))
        };
        let lit = |model: &AppearanceModel, view: usize, c: Vec3| {
            let (g, o) = model.transform(view);
            g * c + o
        };
        let before = [0, 1].map(|v| lit(&model, v, colour(&splats)));
        let (gain, offset) = model.recentre();
        fold_into_colours(&mut splats, gain, offset);
        for (v, before) in before.iter().enumerate() {
            let after = lit(&model, v, colour(&splats));
            assert!(
                (after - *before).abs().max_element() < 1e-5,
                "{after} {before}"
            );
        }
        let (g0, o0) = model.transform(0);
        let (g1, o1) = model.transform(1);
        assert!(((g0 + g1) / 2.0 - Vec3::ONE).abs().max_element() < 1e-6);
        assert!(((o0 + o1) / 2.0).abs().max_element() < 1e-6);
    }

    #[test]
    fn a_darker_photo_is_explained_by_its_transform() {
        // The render is right; the photo is the render at 0.7 gain and +0.05 offset. Minimising
        // the squared error through the transform alone must find them.
        let render: Vec<f32> = (0..300).map(|i| (i % 17) as f32 / 20.0 + 0.1).collect();
        let photo: Vec<f32> = render.iter().map(|&c| 0.7 * c + 0.05).collect();
        let mut model = AppearanceModel::new(
            1,
            AppearanceConfig {
                lr: 0.01,
                prior: 0.0,
                start_step: 0,
            },
        );
        let mut out = Vec::new();
        for _ in 0..1500 {
            model.apply(0, &render, &mut out);
            let mut v: Vec<f32> = out
                .iter()
                .zip(&photo)
                .map(|(a, b)| 2.0 * (a - b) / out.len() as f32)
                .collect();
            model.backward_and_step(0, &render, &mut v);
        }
        let (gain, offset) = model.transform(0);
        assert!(
            (gain - Vec3::splat(0.7)).abs().max_element() < 0.02,
            "{gain}"
        );
        assert!(
            (offset - Vec3::splat(0.05)).abs().max_element() < 0.02,
            "{offset}"
        );
    }

    #[test]
    fn the_render_gradient_is_scaled_by_the_gain() {
        let mut model = AppearanceModel::new(1, AppearanceConfig::default());
        model.views[0].params = [2.0, 0.5, 1.0, 0.0, 0.0, 0.0];
        let mut v = vec![1.0, 1.0, 1.0];
        model.backward_and_step(0, &[0.5, 0.5, 0.5], &mut v);
        assert_eq!(v, vec![2.0, 0.5, 1.0]);
    }
}
