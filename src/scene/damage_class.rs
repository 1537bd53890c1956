//! The damage classes (QuakeCity's three) and their display colours. The identifiers name mask
//! folders, JSON keys and PLY properties, so they never change spelling. They live beneath `scene`
//! because the readers name files by them; `damage` re-exports them.

use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DamageClass {
    Crack,
    Spalling,
    Rebar,
}

impl DamageClass {
    /// All classes in channel order: label channel `k` of a splat is `ALL[k]`.
    pub const ALL: [DamageClass; 3] = [
        DamageClass::Crack,
        DamageClass::Spalling,
        DamageClass::Rebar,
    ];

    /// The identifier used on disk and in JSON.
    pub fn id(self) -> &'static str {
        match self {
            DamageClass::Crack => "crack",
            DamageClass::Spalling => "spalling",
            DamageClass::Rebar => "rebar",
        }
    }

    pub fn from_id(id: &str) -> Option<DamageClass> {
        DamageClass::ALL.into_iter().find(|c| c.id() == id)
    }

    /// Index of this class's label channel.
    pub fn channel(self) -> usize {
        self as usize
    }

    /// QuakeCity's overlay colour (DESIGN.md); user settings may override it.
    pub fn default_colour(self) -> [u8; 3] {
        match self {
            DamageClass::Crack => [255, 0, 0],
            DamageClass::Spalling => [255, 192, 203],
            DamageClass::Rebar => [255, 255, 50],
        }
    }
}

/// Colour of damage that appeared after an earlier survey.
pub const NEW_DAMAGE_COLOUR: [u8; 3] = [0, 255, 0];

impl std::fmt::Display for DamageClass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.id())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_round_trip_and_order_channels() {
        for (k, c) in DamageClass::ALL.into_iter().enumerate() {
            assert_eq!(DamageClass::from_id(c.id()), Some(c));
            assert_eq!(c.channel(), k);
        }
        assert_eq!(DamageClass::from_id("spall"), None);
    }
}
