//! `Splats`: every Gaussian parameter in its pre-activation form, one `Vec` per parameter.

use glam::{Quat, Vec3};

/// The bits of `SplatMeta::state` (DESIGN.md: one byte per Gaussian, saved as the `uchar state`
/// PLY property). Selection and edits are bit operations, so undo is their inverse.
pub mod state {
    pub const SELECTED: u8 = 1;
    pub const HIDDEN: u8 = 2;
    pub const LOCKED: u8 = 4;
    /// Soft deletion: kept in the file, never rendered or trained.
    pub const DELETED: u8 = 8;
    /// Trained by a hierarchical refinement (fine where the damage is).
    pub const REFINED: u8 = 16;
}

/// `SplatMeta::damage_survey` of a Gaussian never seen as damage.
pub const NO_SURVEY: u16 = u16::MAX;

/// Per-Gaussian bookkeeping, kept beside (not inside) the trainable parameters.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SplatMeta {
    /// Stable identity across densification, saves and surveys.
    pub ids: Vec<u64>,
    /// Survey index in which the Gaussian appeared or last changed.
    pub survey: Vec<u16>,
    /// Survey index in which the Gaussian was first seen as damage (`NO_SURVEY`: never).
    pub damage_survey: Vec<u16>,
    /// `state` bits (selected, hidden, locked, deleted, refined).
    pub state: Vec<u8>,
    /// Frozen Gaussians are rendered but never updated (a run's setting, not saved).
    pub frozen: Vec<bool>,
}

impl SplatMeta {
    /// Appends the bookkeeping of a new Gaussian: no state, never damage, not frozen.
    pub fn push(&mut self, id: u64, survey: u16) {
        self.ids.push(id);
        self.survey.push(survey);
        self.damage_survey.push(NO_SURVEY);
        self.state.push(0);
        self.frozen.push(false);
    }

    /// Whether Gaussian `g` has every bit of `bits` set.
    pub fn has(&self, g: usize, bits: u8) -> bool {
        self.state[g] & bits == bits
    }
}

/// Gaussians as structure of arrays. Quaternions are glam's (x, y, z, w) in memory; PLY and
/// gsplat store (w, x, y, z) and convert at their edges.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Splats {
    /// Degree of the SH colour (0..=3); each Gaussian has `(deg+1)^2` coefficients per channel.
    pub sh_degree: u32,
    pub means: Vec<Vec3>,
    /// Natural log of the per-axis standard deviations.
    pub log_scales: Vec<Vec3>,
    /// Un-normalised rotations; normalised when used.
    pub rotations: Vec<Quat>,
    /// Opacity logits: opacity = sigmoid(raw_opacity).
    pub raw_opacities: Vec<f32>,
    /// SH coefficients, Gaussian-major then coefficient then RGB:
    /// `sh[(g * coeffs_per_channel + k) * 3 + c]`, DC first (`k = 0`).
    pub sh: Vec<f32>,
    /// Damage label logits, `raw_labels[g * label_channels + k]`; empty when `label_channels` is 0.
    pub raw_labels: Vec<f32>,
    pub label_channels: usize,
    pub meta: SplatMeta,
    /// The class colours of an overlay-mode model (None for other models): what its painted
    /// damage means, saved with it so that reading the damage back needs no flags.
    pub overlay: Option<OverlayColours>,
}

/// The colours an overlay-mode model was trained to paint its damage in, one per damage class
/// (in class-channel order: crack, spalling, rebar), and the distance (8-bit RGB units) within
/// which a Gaussian's base colour reads as a class colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OverlayColours {
    pub colours: [[u8; 3]; 3],
    pub tolerance: f32,
}

impl OverlayColours {
    /// The PLY header comment's text after `comment `: `damage_twin overlay_colours r,g,b r,g,b
    /// r,g,b tolerance T`.
    pub fn to_comment(&self) -> String {
        let rgb = |c: [u8; 3]| format!("{},{},{}", c[0], c[1], c[2]);
        format!(
            "{OVERLAY_COMMENT} {} {} {} tolerance {}",
            rgb(self.colours[0]),
            rgb(self.colours[1]),
            rgb(self.colours[2]),
            self.tolerance
        )
    }

    /// Parses `to_comment`'s text; None when `text` is another comment, an error when it is
    /// ours but malformed.
    pub fn from_comment(text: &str) -> Option<Result<OverlayColours, String>> {
        let rest = text.strip_prefix(OVERLAY_COMMENT)?;
        let bad = || format!("malformed `{OVERLAY_COMMENT}` comment {text:?}");
        let parse = || -> Option<OverlayColours> {
            let words: Vec<&str> = rest.split_ascii_whitespace().collect();
            let [a, b, c, "tolerance", t] = words[..] else {
                return None;
            };
            let rgb = |w: &str| -> Option<[u8; 3]> {
                let v: Vec<u8> = w
                    .split(',')
                    .map(|x| x.parse().ok())
                    .collect::<Option<_>>()?;
                v.try_into().ok()
            };
            let tolerance: f32 = t
                .parse()
                .ok()
                .filter(|t: &f32| t.is_finite() && *t >= 0.0)?;
            Some(OverlayColours {
                colours: [rgb(a)?, rgb(b)?, rgb(c)?],
                tolerance,
            })
        };
        Some(parse().ok_or_else(bad))
    }
}

/// How the overlay colours' PLY header comment starts.
const OVERLAY_COMMENT: &str = "damage_twin overlay_colours";

/// Most damage label channels a model may carry: the one limit every layer shares (the PLY
/// reader refuses more; the CPU rasterizer's per-tile scratch, the trainer's loss and the GPU
/// kernels are sized for it). Three classes are used; eight leaves room for user classes.
pub const MAX_LABEL_CHANNELS: usize = 8;

/// Highest SH degree of the 3DGS layout (16 coefficients per channel), the most the renderer
/// evaluates and the PLY format stores.
pub const MAX_SH_DEGREE: u32 = 3;

/// SH coefficients per colour channel for a degree. Computed in `usize` and saturating, so a
/// degree no model can have (up to `u32::MAX`) gives a huge count instead of a wrapped one.
pub const fn sh_coeffs_for_degree(degree: u32) -> usize {
    let side = degree as usize + 1;
    side.saturating_mul(side)
}

/// The SH DC constant `Y_0^0 = 1 / (2 sqrt(pi))`: colour = SH · Y + 0.5.
pub const SH_C0: f32 = 0.282_094_8;

impl Splats {
    /// An empty model of a given SH degree and label channel count.
    pub fn empty(sh_degree: u32, label_channels: usize) -> Splats {
        Splats {
            sh_degree,
            label_channels,
            ..Default::default()
        }
    }

    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// SH coefficients per colour channel.
    pub fn sh_coeffs(&self) -> usize {
        sh_coeffs_for_degree(self.sh_degree)
    }

    /// One Gaussian's SH coefficients (`coeffs × 3`).
    pub fn sh_of(&self, g: usize) -> &[f32] {
        let n = self.sh_coeffs() * 3;
        &self.sh[g * n..(g + 1) * n]
    }

    /// One Gaussian's label logits.
    pub fn labels_of(&self, g: usize) -> &[f32] {
        let n = self.label_channels;
        &self.raw_labels[g * n..(g + 1) * n]
    }

    /// Appends a Gaussian. `sh` holds `sh_coeffs() * 3` values; `labels` `label_channels` values.
    #[allow(clippy::too_many_arguments)]
    pub fn push(
        &mut self,
        mean: Vec3,
        log_scale: Vec3,
        rotation: Quat,
        raw_opacity: f32,
        sh: &[f32],
        labels: &[f32],
        id: u64,
        survey: u16,
    ) {
        debug_assert_eq!(sh.len(), self.sh_coeffs() * 3);
        debug_assert_eq!(labels.len(), self.label_channels);
        self.means.push(mean);
        self.log_scales.push(log_scale);
        self.rotations.push(rotation);
        self.raw_opacities.push(raw_opacity);
        self.sh.extend_from_slice(sh);
        self.raw_labels.extend_from_slice(labels);
        self.meta.push(id, survey);
    }

    /// Keeps only the Gaussians where `keep[g]` is true, preserving order.
    pub fn retain(&mut self, keep: &[bool]) {
        assert_eq!(keep.len(), self.len());
        fn filter<T: Copy>(v: &mut Vec<T>, keep: &[bool], stride: usize) {
            let mut w = 0;
            for (g, &k) in keep.iter().enumerate() {
                if k {
                    v.copy_within(g * stride..(g + 1) * stride, w * stride);
                    w += 1;
                }
            }
            v.truncate(w * stride);
        }
        let sh_stride = self.sh_coeffs() * 3;
        filter(&mut self.means, keep, 1);
        filter(&mut self.log_scales, keep, 1);
        filter(&mut self.rotations, keep, 1);
        filter(&mut self.raw_opacities, keep, 1);
        filter(&mut self.sh, keep, sh_stride);
        filter(&mut self.raw_labels, keep, self.label_channels);
        filter(&mut self.meta.ids, keep, 1);
        filter(&mut self.meta.survey, keep, 1);
        filter(&mut self.meta.damage_survey, keep, 1);
        filter(&mut self.meta.state, keep, 1);
        filter(&mut self.meta.frozen, keep, 1);
    }

    /// Raises or lowers the SH degree, keeping the shared coefficients and zero-filling new ones.
    pub fn set_sh_degree(&mut self, degree: u32) {
        let old = self.sh_coeffs();
        let new = sh_coeffs_for_degree(degree);
        if old == new {
            self.sh_degree = degree;
            return;
        }
        let mut sh = vec![0.0; self.len() * new * 3];
        let common = old.min(new) * 3;
        for g in 0..self.len() {
            sh[g * new * 3..g * new * 3 + common]
                .copy_from_slice(&self.sh[g * old * 3..g * old * 3 + common]);
        }
        self.sh = sh;
        self.sh_degree = degree;
    }

    /// Checks that every array has the length the Gaussian count implies.
    pub fn check_lengths(&self) -> Result<(), String> {
        let n = self.len();
        if self.label_channels > MAX_LABEL_CHANNELS {
            return Err(format!(
                "{} label channels; at most {MAX_LABEL_CHANNELS} are supported",
                self.label_channels
            ));
        }
        let checks = [
            ("log_scales", self.log_scales.len(), n),
            ("rotations", self.rotations.len(), n),
            ("raw_opacities", self.raw_opacities.len(), n),
            ("sh", self.sh.len(), n * self.sh_coeffs() * 3),
            ("raw_labels", self.raw_labels.len(), n * self.label_channels),
            ("meta.ids", self.meta.ids.len(), n),
            ("meta.survey", self.meta.survey.len(), n),
            ("meta.damage_survey", self.meta.damage_survey.len(), n),
            ("meta.state", self.meta.state.len(), n),
            ("meta.frozen", self.meta.frozen.len(), n),
        ];
        for (name, got, want) in checks {
            if got != want {
                return Err(format!(
                    "{name} has {got} values, expected {want} for {n} Gaussians"
                ));
            }
        }
        Ok(())
    }
}

/// Logistic sigmoid.
#[inline]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Inverse sigmoid, clamped away from 0 and 1 so it stays finite.
#[inline]
pub fn logit(p: f32) -> f32 {
    let p = p.clamp(1e-6, 1.0 - 1e-6);
    (p / (1.0 - p)).ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_gaussians() -> Splats {
        let mut s = Splats::empty(1, 2);
        let sh0: Vec<f32> = (0..12).map(|v| v as f32).collect();
        let sh1: Vec<f32> = (100..112).map(|v| v as f32).collect();
        s.push(
            Vec3::X,
            Vec3::ZERO,
            Quat::IDENTITY,
            0.0,
            &sh0,
            &[1.0, 2.0],
            7,
            0,
        );
        s.push(
            Vec3::Y,
            Vec3::ONE,
            Quat::IDENTITY,
            1.0,
            &sh1,
            &[3.0, 4.0],
            8,
            1,
        );
        s
    }

    #[test]
    fn retain_keeps_strided_arrays_aligned() {
        let mut s = two_gaussians();
        s.retain(&[false, true]);
        assert_eq!(s.len(), 1);
        assert_eq!(s.means[0], Vec3::Y);
        assert_eq!(s.sh_of(0)[0], 100.0);
        assert_eq!(s.labels_of(0), &[3.0, 4.0]);
        assert_eq!(s.meta.ids, vec![8]);
        s.check_lengths().unwrap();
    }

    #[test]
    fn raising_sh_degree_keeps_low_coefficients() {
        let mut s = two_gaussians();
        s.set_sh_degree(3);
        assert_eq!(s.sh_of(1).len(), 48);
        assert_eq!(
            &s.sh_of(1)[..12],
            &(100..112).map(|v| v as f32).collect::<Vec<_>>()[..]
        );
        assert!(s.sh_of(1)[12..].iter().all(|&v| v == 0.0));
        s.check_lengths().unwrap();
    }

    #[test]
    fn logit_inverts_sigmoid() {
        for p in [0.01f32, 0.1, 0.5, 0.9] {
            assert!((sigmoid(logit(p)) - p).abs() < 1e-6);
        }
    }
}
