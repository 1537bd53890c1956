//! Agreement of rendered damage with reference masks, per class over many views: IoU, precision,
//! recall and F1. Label mode reads the blended label channels at 0.5; overlay mode reads each
//! Gaussian's class from its base colour and renders that as label channels (or, as the
//! published method does, reads class colours back from the RGB render).

use std::borrow::Cow;
use std::collections::BTreeMap;

use glam::Vec3;
use serde::Serialize;

use crate::damage::overlay::{detect_overlay, labels_from_colours, nest_rebar_in_spalling};
use crate::damage::{DamageClass, Palette, TrainMode};
use crate::metrics::MaskAgreement;
use crate::raster::{Rasterizer, RenderOutput, RenderSettings};
use crate::scene::{Camera, Mask};
use crate::splats::Splats;

/// A rendered label channel above this is damage.
pub const LABEL_THRESHOLD: f32 = 0.5;

/// How rendered damage is read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DamageReadout {
    pub mode: TrainMode,
    pub palette: Palette,
    /// Overlay mode: colour distance (8-bit RGB units) within which a base colour (or a
    /// rendered pixel) is a class colour.
    pub tolerance: f32,
    /// Overlay mode: where the colours are read.
    pub overlay_source: OverlaySource,
}

/// Where overlay mode reads the class colours.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum OverlaySource {
    /// Each Gaussian's base colour gives its class, rendered as label channels: a blended edge
    /// or a view-dependent tint cannot push damage out of tolerance (docs/DAMAGE.md, demo
    /// building, chosen colours: held-out IoU +0.01 cracks, +0.09 spalling, +0.06 rebar over
    /// `Pixels`).
    #[default]
    Gaussians,
    /// The rendered RGB pixels, as the published method reads its renders.
    Pixels,
}

impl std::str::FromStr for OverlaySource {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "gaussians" => Ok(OverlaySource::Gaussians),
            "pixels" => Ok(OverlaySource::Pixels),
            _ => Err(format!(
                "unknown overlay readout {text:?}: use gaussians or pixels"
            )),
        }
    }
}

impl DamageReadout {
    /// Label mode when the model carries label channels, else overlay mode, in the colours the
    /// model was trained with when it saved them (`Splats::overlay`), else in `palette`.
    pub fn for_model(splats: &Splats, palette: Palette) -> DamageReadout {
        let mode = if splats.label_channels >= DamageClass::ALL.len() {
            TrainMode::Label
        } else {
            TrainMode::Overlay
        };
        let (palette, tolerance) = match &splats.overlay {
            Some(overlay) => (Palette::from_overlay(overlay), overlay.tolerance),
            None => (palette, crate::damage::overlay::OVERLAY_TOLERANCE),
        };
        DamageReadout {
            mode,
            palette,
            tolerance,
            overlay_source: OverlaySource::default(),
        }
    }

    /// The model to render for this readout and the readout of that render: reading overlay
    /// colours from the Gaussians turns them into label channels first.
    pub fn prepare<'a>(&self, splats: &'a Splats) -> (Cow<'a, Splats>, DamageReadout) {
        if self.mode == TrainMode::Overlay && self.overlay_source == OverlaySource::Gaussians {
            let labelled = labels_from_colours(splats, &self.palette, self.tolerance);
            let readout = DamageReadout {
                mode: TrainMode::Label,
                ..*self
            };
            (Cow::Owned(labelled), readout)
        } else {
            (Cow::Borrowed(splats), *self)
        }
    }
}

/// Per class the predicted mask of one render (`DamageClass::ALL` order). Label mode on a model
/// without label channels, and RGB mode, predict nothing.
pub fn predicted_masks(out: &RenderOutput, readout: &DamageReadout) -> Vec<Mask> {
    predicted_masks_at(out, readout, LABEL_THRESHOLD)
}

/// `predicted_masks` with another label-mode threshold: a label channel above
/// `label_threshold` is damage (overlay mode reads colours as before).
pub fn predicted_masks_at(
    out: &RenderOutput,
    readout: &DamageReadout,
    label_threshold: f32,
) -> Vec<Mask> {
    let (w, h) = (out.width, out.height);
    match readout.mode {
        TrainMode::Overlay => {
            let mut masks = detect_overlay(&out.color, w, h, &readout.palette, readout.tolerance);
            nest_rebar_in_spalling(&mut masks);
            masks
        }
        TrainMode::Label if out.label_channels >= DamageClass::ALL.len() => DamageClass::ALL
            .iter()
            .map(|class| {
                let k = class.channel();
                Mask {
                    width: w,
                    height: h,
                    data: out
                        .labels
                        .chunks_exact(out.label_channels)
                        .map(|l| u8::from(l[k] > label_threshold))
                        .collect(),
                }
            })
            .collect(),
        _ => DamageClass::ALL.iter().map(|_| Mask::empty(w, h)).collect(),
    }
}

/// Per-class pixel counts over the evaluated views.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DamageScores {
    pub views: usize,
    /// Classes that had a reference mask in at least one view.
    pub classes: BTreeMap<DamageClass, MaskAgreement>,
}

impl DamageScores {
    /// Adds one view: `predicted` and `reference` per class in `DamageClass::ALL` order; a class
    /// without a reference mask is not counted.
    pub fn add_view(&mut self, predicted: &[Mask], reference: &[Option<Mask>]) {
        self.add_view_where(predicted, reference, None);
    }

    /// `add_view` counting only the pixels `used` marks (an ignore mask, 1 = use; all when
    /// None or of another size).
    pub fn add_view_where(
        &mut self,
        predicted: &[Mask],
        reference: &[Option<Mask>],
        used: Option<&Mask>,
    ) {
        self.views += 1;
        for ((class, p), r) in DamageClass::ALL.iter().zip(predicted).zip(reference) {
            let Some(r) = r else { continue };
            if p.data.len() != r.data.len() {
                continue;
            }
            let used = used.filter(|u| u.data.len() == p.data.len());
            let pairs = p
                .data
                .iter()
                .zip(&r.data)
                .enumerate()
                .filter(|&(i, _)| used.is_none_or(|u| u.data[i] != 0));
            let (predicted, reference): (Vec<bool>, Vec<bool>) =
                pairs.map(|(_, (&a, &b))| (a != 0, b != 0)).unzip();
            self.classes
                .entry(*class)
                .or_default()
                .accumulate(predicted, reference);
        }
    }

    /// One figure per class, keyed by class identifier (the JSON shape of `eval --json`).
    pub fn per_class(&self, figure: impl Fn(&MaskAgreement) -> f64) -> BTreeMap<String, f64> {
        self.classes
            .iter()
            .map(|(class, a)| (class.id().to_string(), figure(a)))
            .collect()
    }
}

/// Per-class figures, the JSON shape of `eval --json` and `metrics.json`: class → value.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DamageFigures {
    /// Views evaluated.
    pub mask_views: usize,
    pub iou: BTreeMap<String, f64>,
    pub precision: BTreeMap<String, f64>,
    pub recall: BTreeMap<String, f64>,
    pub f1: BTreeMap<String, f64>,
    /// Reference damage pixels per class (how much there was to find).
    pub reference_pixels: BTreeMap<String, u64>,
}

impl DamageScores {
    pub fn figures(&self) -> DamageFigures {
        DamageFigures {
            mask_views: self.views,
            iou: self.per_class(MaskAgreement::iou),
            precision: self.per_class(MaskAgreement::precision),
            recall: self.per_class(MaskAgreement::recall),
            f1: self.per_class(MaskAgreement::f1),
            reference_pixels: self
                .classes
                .iter()
                .map(|(c, a)| (c.id().to_string(), a.true_positive + a.false_negative))
                .collect(),
        }
    }
}

/// One view to evaluate: its camera (at the evaluation scale) and reference masks.
pub struct ReferenceView {
    pub name: String,
    pub camera: Camera,
    pub reference: Vec<Option<Mask>>,
    /// The view's ignore mask (1 = use): ignored pixels are not scored.
    pub used: Option<Mask>,
}

/// Renders every view and scores its damage against the references.
pub fn evaluate_damage(
    splats: &Splats,
    views: &[ReferenceView],
    readout: &DamageReadout,
    background: Vec3,
) -> DamageScores {
    let settings = RenderSettings::new(background, splats.sh_degree);
    let (splats, readout) = readout.prepare(splats);
    let mut rasterizer = Rasterizer::new();
    let mut out = RenderOutput::default();
    let mut scores = DamageScores::default();
    for view in views {
        rasterizer.forward(&splats, &view.camera, &settings, &mut out);
        score_render(&mut scores, &out, view, &readout);
    }
    scores
}

/// Adds `view`'s damage as the render `out` of it shows it (a render of the model `readout`
/// prepared, as `evaluate_damage` makes it) to `scores`: for a caller that renders the view for
/// another figure too.
pub fn score_render(
    scores: &mut DamageScores,
    out: &RenderOutput,
    view: &ReferenceView,
    readout: &DamageReadout,
) {
    let predicted = predicted_masks(out, readout);
    scores.add_view_where(&predicted, &view.reference, view.used.as_ref());
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(bits: &[u8]) -> Mask {
        Mask {
            width: bits.len() as u32,
            height: 1,
            data: bits.to_vec(),
        }
    }

    #[test]
    fn ignored_pixels_are_not_scored() {
        let predicted = [mask(&[1, 1, 0, 0]), mask(&[0; 4]), mask(&[0; 4])];
        let reference = [Some(mask(&[1, 0, 1, 0])), None, None];
        let mut all = DamageScores::default();
        all.add_view(&predicted, &reference);
        // The false positive (pixel 1) and the miss (pixel 2) lie where the ignore mask is 0.
        let mut used = DamageScores::default();
        used.add_view_where(&predicted, &reference, Some(&mask(&[1, 0, 0, 1])));
        assert!((all.per_class(MaskAgreement::iou)["crack"] - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(used.per_class(MaskAgreement::iou)["crack"], 1.0);
    }

    #[test]
    fn scores_count_only_classes_with_a_reference() {
        let mut scores = DamageScores::default();
        let predicted = [
            mask(&[1, 1, 0, 0]),
            mask(&[0, 0, 0, 1]),
            mask(&[1, 1, 1, 1]),
        ];
        let reference = [Some(mask(&[1, 0, 1, 0])), Some(mask(&[0, 0, 0, 1])), None];
        scores.add_view(&predicted, &reference);
        let iou = scores.per_class(MaskAgreement::iou);
        assert_eq!(iou.len(), 2);
        assert!((iou["crack"] - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(iou["spalling"], 1.0);
        assert!((scores.per_class(MaskAgreement::precision)["crack"] - 0.5).abs() < 1e-12);
    }

    #[test]
    fn label_channels_are_read_at_one_half() {
        let out = RenderOutput {
            width: 2,
            height: 1,
            label_channels: 3,
            labels: vec![0.6, 0.2, 0.0, 0.4, 0.9, 0.51],
            ..RenderOutput::default()
        };
        let readout = DamageReadout {
            mode: TrainMode::Label,
            palette: Palette::default(),
            tolerance: 40.0,
            overlay_source: OverlaySource::Gaussians,
        };
        let masks = predicted_masks(&out, &readout);
        assert_eq!(masks[0].data, vec![1, 0]);
        assert_eq!(masks[1].data, vec![0, 1]);
        assert_eq!(masks[2].data, vec![0, 1]);
    }

    /// `score_render` on a render made by `raster::render` (a fresh rasterizer, as the
    /// refinement's scoring makes it for the PSNR too) gives `evaluate_damage`'s scores, whose
    /// rasterizer is reused across the views: the scoring may share one render per view.
    #[test]
    fn scoring_a_shared_render_is_evaluating() {
        use crate::scene::Intrinsics;
        use glam::Quat;
        let mut model = Splats::empty(0, 3);
        let sh = vec![0.0; model.sh_coeffs() * 3];
        for i in 0..40 {
            let (x, y) = ((i % 8) as f32 * 0.3 - 1.0, (i / 8) as f32 * 0.3 - 0.6);
            let crack = if i % 3 == 0 { 3.0 } else { -3.0 };
            model.push(
                Vec3::new(x, y, 5.0 + 0.01 * i as f32),
                Vec3::splat((0.12f32).ln()),
                Quat::IDENTITY,
                1.5,
                &sh,
                &[crack, -3.0, if i % 5 == 0 { 2.0 } else { -3.0 }],
                i,
                crate::splats::model::NO_SURVEY,
            );
        }
        let k = Intrinsics {
            width: 40,
            height: 30,
            fx: 40.0,
            fy: 40.0,
            cx: 20.0,
            cy: 15.0,
        };
        let views: Vec<ReferenceView> = [0.0f32, 0.2, -0.3]
            .iter()
            .map(|&x| {
                let mut crack = Mask::empty(40, 30);
                for p in (0..crack.data.len()).step_by(3) {
                    crack.data[p] = 1;
                }
                ReferenceView {
                    name: format!("view {x}"),
                    camera: Camera::new(k, Quat::IDENTITY, Vec3::new(x, 0.0, 0.0)),
                    reference: vec![Some(crack), None, Some(Mask::empty(40, 30))],
                    used: None,
                }
            })
            .collect();
        let readout = DamageReadout::for_model(&model, Palette::default());
        let background = Vec3::new(0.1, 0.2, 0.3);
        let whole = evaluate_damage(&model, &views, &readout, background);
        let settings = RenderSettings::new(background, model.sh_degree);
        let mut shared = DamageScores::default();
        for view in &views {
            let out = crate::raster::render(&model, &view.camera, &settings);
            score_render(&mut shared, &out, view, &readout);
        }
        assert_eq!(shared, whole);
        assert!(
            whole.classes.values().any(|a| a.true_positive > 0),
            "{whole:?}"
        );
    }
}
