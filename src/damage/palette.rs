//! The class colours of overlay mode and of the damage layer: DESIGN.md's defaults (QuakeCity),
//! each one overridable (the published method recolours cracks blue on red brick).

use serde::{Deserialize, Serialize};

use crate::damage::DamageClass;
use crate::damage::overlay::OVERLAY_TOLERANCE;
use crate::scene::RgbImage;
use crate::splats::model::OverlayColours;

/// Overlay colours are at least this far apart (8-bit RGB units), so that two classes never
/// read as each other.
const MIN_CLASS_SEPARATION: f32 = 200.0;

/// The fraction of photo pixels allowed nearer to a class colour than its contrast: a few
/// stray pixels (a red sign, a blue tarpaulin) must not rule a colour out.
const CONTRAST_QUANTILE: f64 = 0.001;

/// The read-back tolerance is half the chosen colours' contrast, within these bounds: 40 is the
/// colour-coded mask reader's tolerance, and past 100 a blend of half damage and half wall
/// (the edge of a painted crack) would read as damage.
const TOLERANCE_RANGE: (f32, f32) = (OVERLAY_TOLERANCE, 100.0);

/// One sRGB colour per class, in `DamageClass::ALL` order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Palette {
    pub colours: [[u8; 3]; 3],
}

impl Default for Palette {
    fn default() -> Self {
        Palette {
            colours: DamageClass::ALL.map(|c| c.default_colour()),
        }
    }
}

impl Palette {
    pub fn colour(&self, class: DamageClass) -> [u8; 3] {
        self.colours[class.channel()]
    }

    /// The colour as linear [0, 1] floats, the unit of `RgbImage` and renders.
    pub fn unit_colour(&self, class: DamageClass) -> [f32; 3] {
        self.colour(class).map(|c| f32::from(c) / 255.0)
    }

    /// Applies an override written `class=r,g,b` (bytes), e.g. `crack=0,0,255`.
    pub fn set_from_text(&mut self, text: &str) -> Result<(), String> {
        let bad = || format!("bad class colour {text:?}: use class=r,g,b, e.g. crack=0,0,255");
        let (name, rgb) = text.split_once('=').ok_or_else(bad)?;
        let class = DamageClass::from_id(name.trim()).ok_or_else(|| {
            format!("unknown damage class {name:?} in {text:?}: use crack, spalling or rebar")
        })?;
        let bytes: Vec<u8> = rgb
            .split(',')
            .map(|v| v.trim().parse::<u8>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad())?;
        let [r, g, b] = bytes[..] else {
            return Err(bad());
        };
        self.colours[class.channel()] = [r, g, b];
        Ok(())
    }

    /// Overlay colours for a scene, chosen against its photos as the published method recolours
    /// cracks blue on red brick: of the saturated colours of the RGB cube (channels 0, 128 or
    /// 255, at least one 0 and one 255), the thin classes (cracks, then rebar, then spalling)
    /// take in turn the colour farthest from the photos' colours (its distance to the nearest
    /// photo pixels, ignoring `CONTRAST_QUANTILE` of them) among those at least
    /// `MIN_CLASS_SEPARATION` from the classes already coloured. The tolerance is half the
    /// smallest contrast of the three, within `TOLERANCE_RANGE`. Deterministic for given photos.
    pub fn contrasting(photos: &[&RgbImage]) -> OverlayColours {
        let candidates = saturated_colours();
        let samples = photo_samples(photos, 200_000);
        let contrast: Vec<f32> = candidates
            .iter()
            .map(|&c| contrast_to(&samples, c))
            .collect();
        let mut order: Vec<usize> = (0..candidates.len()).collect();
        // Stable: ties keep the candidates' order.
        order.sort_by(|&a, &b| contrast[b].total_cmp(&contrast[a]));
        let mut colours = DamageClass::ALL.map(|c| c.default_colour());
        let mut chosen: Vec<usize> = Vec::new();
        for class in [
            DamageClass::Crack,
            DamageClass::Rebar,
            DamageClass::Spalling,
        ] {
            let pick = order
                .iter()
                .copied()
                .find(|&i| {
                    !chosen.contains(&i)
                        && chosen.iter().all(|&j| {
                            distance(candidates[i], candidates[j]) >= MIN_CLASS_SEPARATION
                        })
                })
                .unwrap_or(order[chosen.len()]);
            chosen.push(pick);
            colours[class.channel()] = candidates[pick];
        }
        let least = chosen
            .iter()
            .map(|&i| contrast[i])
            .fold(f32::INFINITY, f32::min);
        OverlayColours {
            colours,
            tolerance: (least / 2.0).clamp(TOLERANCE_RANGE.0, TOLERANCE_RANGE.1),
        }
    }

    /// The palette of an overlay model's saved colours.
    pub fn from_overlay(overlay: &OverlayColours) -> Palette {
        Palette {
            colours: overlay.colours,
        }
    }
}

/// The saturated colours of the RGB cube on a 0/128/255 grid: at least one channel 0 and one
/// 255 (no greys, no pastels, which walls, sky and glass come close to).
fn saturated_colours() -> Vec<[u8; 3]> {
    const LEVELS: [u8; 3] = [0, 128, 255];
    let mut out = Vec::new();
    for r in LEVELS {
        for g in LEVELS {
            for b in LEVELS {
                let c = [r, g, b];
                if c.contains(&0) && c.contains(&255) {
                    out.push(c);
                }
            }
        }
    }
    out
}

/// Up to about `most` pixels of the photos, evenly strided, in 8-bit units.
fn photo_samples(photos: &[&RgbImage], most: usize) -> Vec<[f32; 3]> {
    let total: usize = photos.iter().map(|p| p.data.len() / 3).sum();
    let stride = total.div_ceil(most.max(1)).max(1);
    photos
        .iter()
        .flat_map(|p| p.data.chunks_exact(3).step_by(stride))
        .map(|rgb| [rgb[0] * 255.0, rgb[1] * 255.0, rgb[2] * 255.0])
        .collect()
}

/// The distance from `colour` within which `CONTRAST_QUANTILE` of the samples lie (the full
/// cube diagonal when there are none).
fn contrast_to(samples: &[[f32; 3]], colour: [u8; 3]) -> f32 {
    let c = colour.map(f32::from);
    let mut d: Vec<f32> = samples
        .iter()
        .map(|s| ((s[0] - c[0]).powi(2) + (s[1] - c[1]).powi(2) + (s[2] - c[2]).powi(2)).sqrt())
        .filter(|d| d.is_finite())
        .collect();
    if d.is_empty() {
        return 255.0 * 3f32.sqrt();
    }
    let k = ((d.len() as f64 * CONTRAST_QUANTILE) as usize).min(d.len() - 1);
    *d.select_nth_unstable_by(k, f32::total_cmp).1
}

fn distance(a: [u8; 3], b: [u8; 3]) -> f32 {
    (0..3)
        .map(|i| (f32::from(a[i]) - f32::from(b[i])).powi(2))
        .sum::<f32>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overrides_parse_and_bad_ones_are_refused() {
        let mut palette = Palette::default();
        palette.set_from_text("crack=0,0,255").unwrap();
        assert_eq!(palette.colour(DamageClass::Crack), [0, 0, 255]);
        assert_eq!(palette.colour(DamageClass::Spalling), [255, 192, 203]);
        for bad in ["crack", "dent=1,2,3", "crack=1,2", "crack=1,2,300"] {
            assert!(palette.set_from_text(bad).is_err(), "{bad}");
        }
    }

    fn flat(width: u32, height: u32, rgb: [f32; 3]) -> RgbImage {
        RgbImage {
            width,
            height,
            data: (0..width * height).flat_map(|_| rgb).collect(),
        }
    }

    #[test]
    fn contrasting_colours_avoid_the_photos_and_each_other() {
        // A red-brick wall and a blue sky: cracks must not be red or blue.
        let brick = flat(8, 8, [0.63, 0.41, 0.31]);
        let sky = flat(8, 2, [0.5, 0.63, 0.85]);
        let chosen = Palette::contrasting(&[&brick, &sky]);
        let photo = |rgb: [f32; 3]| rgb.map(|v| (v * 255.0) as u8);
        for colour in chosen.colours {
            for wall in [photo([0.63, 0.41, 0.31]), photo([0.5, 0.63, 0.85])] {
                assert!(
                    distance(colour, wall) + 1.0 >= 2.0 * chosen.tolerance,
                    "{colour:?}"
                );
            }
        }
        for (i, a) in chosen.colours.iter().enumerate() {
            for b in &chosen.colours[i + 1..] {
                assert!(distance(*a, *b) >= MIN_CLASS_SEPARATION, "{a:?} {b:?}");
            }
        }
        assert!((TOLERANCE_RANGE.0..=TOLERANCE_RANGE.1).contains(&chosen.tolerance));
        // The same photos give the same colours.
        assert_eq!(chosen, Palette::contrasting(&[&brick, &sky]));
        // A photo the colour of the best candidate moves the cracks off it.
        let first = chosen.colours[DamageClass::Crack.channel()];
        let painted = flat(4, 4, first.map(|c| f32::from(c) / 255.0));
        let moved = Palette::contrasting(&[&brick, &sky, &painted]);
        assert_ne!(moved.colours[DamageClass::Crack.channel()], first);
    }
}
