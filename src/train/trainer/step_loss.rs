//! The loss of one step and its gradient with respect to the render (`Trainer::render_loss`):
//! photometric (L1 + D-SSIM, through the photo's learnt light when there is one) and label
//! cross-entropy, inside the view's loss region. Shared by the CPU step and the GPU-resident one.

use super::Trainer;
use crate::raster::MAX_LABEL_CHANNELS;
use crate::train::adam::ParamGroup;
use crate::train::label_loss::label_loss;
use crate::train::loss::photometric_loss;
use crate::train::spec::DETACHED_LABEL_SCALE;

impl Trainer {
    /// The label loss's weight at `step`: the set weight while the label loss shapes the
    /// geometry, scaled by `DETACHED_LABEL_SCALE` after `Targets::label_geometry_steps`.
    pub(super) fn label_weight_at(&self, step: u32) -> f32 {
        let targets = &self.spec.targets;
        match targets.label_geometry_steps {
            Some(until) if step > until => targets.label_weight * DETACHED_LABEL_SCALE,
            _ => targets.label_weight,
        }
    }

    /// At the first step past `Targets::label_geometry_steps`, scales the label logits' Adam
    /// moments (and the checkpoint's, which predates the switch) as the loss is scaled, so the
    /// logits keep their step sizes while the geometry stops feeling the label loss.
    pub(super) fn detach_labels_if_due(&mut self, step: u32) {
        if step == 0 || self.spec.targets.label_geometry_steps != Some(step - 1) {
            return;
        }
        self.sync();
        for adam in [&mut self.adam, &mut self.checkpoint.adam] {
            adam.scale_moments(ParamGroup::RawLabels, DETACHED_LABEL_SCALE);
        }
        if let Some(r) = &mut self.resident {
            r.dirty = true;
        }
    }

    /// The loss of the frame in `self.out` against view `view_index`; its gradients land in
    /// `self.v_color` (and `self.v_labels` when the second value, labels on, is true).
    pub(super) fn render_loss(&mut self, view_index: usize, step: u32) -> (f32, bool) {
        let view = &self.views[view_index];
        let region = self.regions[view_index].as_deref();
        let targets = self.spec.targets;
        let label_weight = self.label_weight_at(step);
        self.v_color.resize(self.out.color.len(), 0.0);
        let mut loss = 0.0f32;
        if targets.rgb_weight > 0.0 {
            // Through the photo's light, when it is learnt: the loss compares that with the photo.
            let appearance = self.appearance.as_mut().filter(|a| a.active_at(step));
            let mut lit = std::mem::take(&mut self.lit_color);
            if let Some(appearance) = &appearance {
                appearance.apply(view_index, &self.out.color, &mut lit);
            }
            let rendered = if appearance.is_some() {
                lit.as_slice()
            } else {
                self.out.color.as_slice()
            };
            let photometric = photometric_loss(
                &mut self.loss_ws,
                rendered,
                &view.image.data,
                view.image.width,
                view.image.height,
                region,
                targets.ssim_lambda,
                &mut self.v_color,
            );
            loss += targets.rgb_weight * photometric.loss;
            if targets.rgb_weight != 1.0 {
                self.v_color
                    .iter_mut()
                    .for_each(|v| *v *= targets.rgb_weight);
            }
            self.lit_color = lit;
            if let Some(appearance) = appearance {
                loss +=
                    appearance.backward_and_step(view_index, &self.out.color, &mut self.v_color);
            }
        } else {
            self.v_color.fill(0.0);
        }
        let labels_on = targets.label_weight > 0.0
            && self.splats.label_channels > 0
            && view.labels.len() == self.splats.label_channels
            && self.splats.label_channels <= MAX_LABEL_CHANNELS;
        if labels_on {
            self.v_labels.resize(self.out.labels.len(), 0.0);
            let masks: [Option<&[u8]>; MAX_LABEL_CHANNELS] =
                std::array::from_fn(|k| view.labels.get(k).map(|m| m.data.as_slice()));
            let label = label_loss(
                &self.out.labels,
                self.splats.label_channels,
                &masks[..self.splats.label_channels],
                region,
                &self.label_params,
                &mut self.v_labels,
            );
            // After the switch the loss reported is the one optimised, its label term scaled
            // down with the gradient (as on the GPU, whose loss kernel weights it the same way).
            loss += label_weight * label;
            self.v_labels.iter_mut().for_each(|v| *v *= label_weight);
        }
        (loss, labels_on)
    }
}
