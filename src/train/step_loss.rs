//! The loss of one step and its gradient with respect to the render (`Trainer::render_loss`):
//! photometric (L1 + D-SSIM, through the photo's learnt light when there is one) and label
//! cross-entropy, inside the view's loss region. Shared by the CPU step and the GPU-resident one.

use super::Trainer;
use crate::raster::MAX_LABEL_CHANNELS;
use crate::train::loss::{label_loss, photometric_loss};

impl Trainer {
    /// The loss of the frame in `self.out` against view `view_index`; its gradients land in
    /// `self.v_color` (and `self.v_labels` when the second value, labels on, is true).
    pub(super) fn render_loss(&mut self, view_index: usize, step: u32) -> (f32, bool) {
        let view = &self.views[view_index];
        let region = self.regions[view_index].as_deref();
        let targets = self.spec.targets;
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
            loss += targets.label_weight * label;
            self.v_labels
                .iter_mut()
                .for_each(|v| *v *= targets.label_weight);
        }
        (loss, labels_on)
    }
}
