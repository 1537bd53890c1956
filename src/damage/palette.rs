//! The class colours of overlay mode and of the damage layer: DESIGN.md's defaults (QuakeCity),
//! each one overridable (the published method recolours cracks blue on red brick).

use serde::{Deserialize, Serialize};

use crate::damage::DamageClass;

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
}
