//! Display of the damage layer: class colours over the photo-real render. Per pixel on a CPU
//! render (`composite`), or per Gaussian before rendering or GPU upload (`display_splats`:
//! blending is linear in colour, so tinting each Gaussian by its label probability matches
//! tinting the blended label channels), and the selection's tint. Display only: no evaluation,
//! no thresholds.

use std::borrow::Cow;

use serde::{Deserialize, Serialize};

use crate::scene::DamageClass;
use crate::splats::Splats;
use crate::splats::model::state::{DELETED, HIDDEN, SELECTED};
use crate::splats::model::{SH_C0, sigmoid};

/// How the damage layer is drawn (the viewer's settings, `render --damage-layer`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DamageLayer {
    pub enabled: bool,
    /// Opacity of the class colours over the photo-real render.
    pub opacity: f32,
    /// Show only damage (no photo-real colour).
    pub damage_only: bool,
    /// Per class, in `DamageClass::ALL` order: shown or not.
    pub visible: [bool; 3],
    /// Per class colour (sRGB), in `DamageClass::ALL` order.
    pub colours: [[u8; 3]; 3],
    /// Colour damage by the survey it was first seen in instead of by class
    /// (`display_by_survey`), when `survey_colours` are known.
    pub by_survey: bool,
    /// Per survey index, its damage colour (set by whoever knows the project's surveys; not
    /// a setting).
    #[serde(skip)]
    pub survey_colours: Vec<[u8; 3]>,
    /// The survey the model shown belongs to: its damage without a survey tag was first seen
    /// there.
    #[serde(skip)]
    pub own_survey: u16,
}

/// Colour of damage first seen in an earlier survey than the one shown (the latest survey's
/// takes the project's new-damage colour).
pub const EARLIER_DAMAGE: [u8; 3] = [70, 130, 255];

/// Survey colours for showing survey `shown` (0-based): every earlier survey's damage in
/// `EARLIER_DAMAGE`, that survey's own in `new_colour`.
pub fn survey_colours(shown: usize, new_colour: [u8; 3]) -> Vec<[u8; 3]> {
    let mut colours = vec![EARLIER_DAMAGE; shown];
    colours.push(new_colour);
    colours
}

impl Default for DamageLayer {
    fn default() -> Self {
        DamageLayer {
            enabled: true,
            opacity: 0.7,
            damage_only: false,
            visible: [true; 3],
            colours: DamageClass::ALL.map(|c| c.default_colour()),
            by_survey: false,
            survey_colours: Vec::new(),
            own_survey: 0,
        }
    }
}

/// sRGB byte to linear-ish [0, 1] (renders are stored as [0, 1] colour, no gamma change).
fn unit(c: u8) -> f32 {
    f32::from(c) / 255.0
}

/// Composites the damage layer into `color` (RGB interleaved) from `labels`
/// (`[pixel * channels + k]`). Does nothing when the layer is off or there are no labels.
pub fn composite(color: &mut [f32], labels: &[f32], channels: usize, layer: &DamageLayer) {
    if !layer.enabled || channels == 0 {
        return;
    }
    let pixels = color.len() / 3;
    if labels.len() < pixels * channels {
        return;
    }
    let opacity = layer.opacity.clamp(0.0, 1.0);
    for (px, rgb) in color.chunks_exact_mut(3).enumerate() {
        if layer.damage_only {
            let grey = 0.25 * (rgb[0] + rgb[1] + rgb[2]) / 3.0;
            rgb.iter_mut().for_each(|c| *c = grey);
        }
        let label = &labels[px * channels..(px + 1) * channels];
        for (k, &value) in label.iter().enumerate().take(3) {
            if !layer.visible[k] || !(value > 0.0) {
                continue;
            }
            let w = (value.min(1.0) * opacity).clamp(0.0, 1.0);
            let colour = layer.colours[k];
            for (v, &target) in rgb.iter_mut().zip(&colour) {
                *v += (unit(target) - *v) * w;
            }
        }
    }
}

/// The model as the viewer shows it: scales multiplied by `splat_scale`, and with the damage
/// layer on, each Gaussian's colour tinted towards its classes' colours by label probability ×
/// opacity (damage-only greys the rest). Borrows when nothing changes.
pub fn display_splats<'a>(
    splats: &'a Splats,
    splat_scale: f32,
    layer: &DamageLayer,
) -> Cow<'a, Splats> {
    let scale_changes =
        splat_scale.is_finite() && splat_scale > 0.0 && (splat_scale - 1.0).abs() > 1e-6;
    let damage = layer.enabled && splats.label_channels > 0;
    let by_survey = damage && layer.by_survey && !layer.survey_colours.is_empty();
    let selected = splats.meta.state.iter().any(|&b| b & SELECTED != 0);
    let hidden = splats
        .meta
        .state
        .iter()
        .any(|&b| b & (HIDDEN | DELETED) != 0);
    if !scale_changes && !damage && !selected && !hidden {
        return Cow::Borrowed(splats);
    }
    let mut out = if by_survey {
        display_by_survey(splats, &layer.survey_colours, layer.own_survey)
    } else {
        splats.clone()
    };
    if scale_changes {
        let ln = splat_scale.ln();
        for s in &mut out.log_scales {
            *s += glam::Vec3::splat(ln);
        }
    }
    if damage && !by_survey {
        let k_coeffs = out.sh_coeffs();
        let channels = out.label_channels;
        let opacity = layer.opacity.clamp(0.0, 1.0);
        for g in 0..out.len() {
            let sh = &mut out.sh[g * k_coeffs * 3..(g + 1) * k_coeffs * 3];
            // Colour from the DC term alone (view-independent), as 3DGS: c = SH_C0 · dc + 0.5.
            let mut rgb = [
                SH_C0 * sh[0] + 0.5,
                SH_C0 * sh[1] + 0.5,
                SH_C0 * sh[2] + 0.5,
            ];
            let mut keep = 1.0;
            if layer.damage_only {
                let grey = 0.25 * (rgb[0] + rgb[1] + rgb[2]) / 3.0;
                rgb = [grey; 3];
            }
            let labels = &splats.raw_labels[g * channels..(g + 1) * channels];
            for (k, &raw) in labels.iter().enumerate().take(3) {
                if !layer.visible[k] {
                    continue;
                }
                let w = sigmoid(raw) * opacity;
                if !(w > 0.0) {
                    continue;
                }
                for (v, &target) in rgb.iter_mut().zip(&layer.colours[k]) {
                    *v += (unit(target) - *v) * w;
                }
                keep *= 1.0 - w;
            }
            for (dc, v) in sh.iter_mut().zip(rgb) {
                *dc = (v - 0.5) / SH_C0;
            }
            // View-dependent colour fades where damage is painted (and entirely in damage-only).
            let rest = if layer.damage_only { 0.0 } else { keep };
            for v in &mut sh[3..] {
                *v *= rest;
            }
        }
    }
    if selected {
        tint_selection(&mut out);
    }
    if hidden {
        // Hidden and (soft-)deleted Gaussians stay in the model but draw nothing.
        for (opacity, &bits) in out.raw_opacities.iter_mut().zip(&splats.meta.state) {
            if bits & (HIDDEN | DELETED) != 0 {
                *opacity = -30.0;
            }
        }
    }
    Cow::Owned(out)
}

/// The model with its damage coloured by the survey it was first seen in (`survey_colours`
/// indexed by `damage_survey`; the last colour for any later index; damage without a tag was
/// first seen in `own_survey`, the survey the model belongs to) and the rest greyed: each
/// Gaussian's colour goes to its survey's colour by its highest class probability. View-dependent
/// colour is dropped.
pub fn display_by_survey(splats: &Splats, survey_colours: &[[u8; 3]], own_survey: u16) -> Splats {
    use crate::splats::model::NO_SURVEY;
    let mut out = splats.clone();
    let k_coeffs = out.sh_coeffs();
    let channels = out.label_channels;
    for g in 0..out.len() {
        let sh = &mut out.sh[g * k_coeffs * 3..(g + 1) * k_coeffs * 3];
        let grey = 0.25 * (SH_C0 * (sh[0] + sh[1] + sh[2]) / 3.0 + 0.5);
        let mut rgb = [grey; 3];
        let survey = match splats.meta.damage_survey[g] {
            NO_SURVEY => own_survey,
            tagged => tagged,
        };
        if channels > 0 && !survey_colours.is_empty() {
            let colour = survey_colours[usize::from(survey).min(survey_colours.len() - 1)];
            let w = splats.raw_labels[g * channels..(g + 1) * channels]
                .iter()
                .take(DamageClass::ALL.len())
                .map(|&l| sigmoid(l))
                .fold(0.0f32, f32::max);
            for (v, &target) in rgb.iter_mut().zip(&colour) {
                *v += (unit(target) - *v) * w;
            }
        }
        for (dc, v) in sh.iter_mut().zip(rgb) {
            *dc = (v - 0.5) / SH_C0;
        }
        for v in &mut sh[3..] {
            *v = 0.0;
        }
    }
    out
}

/// Colour the selection is tinted towards (sRGB), and how far.
pub const SELECTION_TINT: [u8; 3] = [255, 140, 0];
const SELECTION_TINT_WEIGHT: f32 = 0.6;

/// Tints the selected Gaussians' base colour towards `SELECTION_TINT`.
fn tint_selection(out: &mut Splats) {
    let k_coeffs = out.sh_coeffs();
    for g in 0..out.len() {
        if out.meta.state[g] & SELECTED == 0 {
            continue;
        }
        let sh = &mut out.sh[g * k_coeffs * 3..(g + 1) * k_coeffs * 3];
        for (dc, &target) in sh.iter_mut().zip(&SELECTION_TINT) {
            let v = SH_C0 * *dc + 0.5;
            *dc = (v + (unit(target) - v) * SELECTION_TINT_WEIGHT - 0.5) / SH_C0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_label_at_full_opacity_paints_the_class_colour() {
        let layer = DamageLayer {
            opacity: 1.0,
            ..DamageLayer::default()
        };
        let mut color = vec![0.5; 6];
        let labels = vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        composite(&mut color, &labels, 3, &layer);
        assert_eq!(&color[..3], &[1.0, 0.0, 0.0]);
        assert_eq!(&color[3..], &[0.5, 0.5, 0.5], "no label, no change");
    }

    #[test]
    fn hidden_class_is_not_drawn() {
        let mut layer = DamageLayer::default();
        layer.visible[0] = false;
        let mut color = vec![0.5; 3];
        composite(&mut color, &[1.0, 0.0, 0.0], 3, &layer);
        assert_eq!(color, vec![0.5; 3]);
    }
}
