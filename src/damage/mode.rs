//! How damage supervises a training run: not at all, painted into the photos (overlay), or as
//! per-Gaussian label channels (label).

use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum TrainMode {
    /// Photos only.
    #[serde(alias = "Rgb")]
    Rgb,
    /// Photos with the damage masks painted on in the class colours (the published method).
    #[serde(alias = "Overlay")]
    Overlay,
    /// Photos as RGB target plus one label channel per damage class (ours).
    #[default]
    #[serde(alias = "Label")]
    Label,
}

impl TrainMode {
    pub const ALL: [TrainMode; 3] = [TrainMode::Rgb, TrainMode::Overlay, TrainMode::Label];

    /// The identifier used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            TrainMode::Rgb => "rgb",
            TrainMode::Overlay => "overlay",
            TrainMode::Label => "label",
        }
    }

    pub fn from_name(name: &str) -> Option<TrainMode> {
        TrainMode::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Whether the mode needs damage masks.
    pub fn uses_masks(self) -> bool {
        self != TrainMode::Rgb
    }
}

impl std::fmt::Display for TrainMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for TrainMode {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        TrainMode::from_name(text)
            .ok_or_else(|| format!("unknown mode {text:?}: use rgb, overlay or label"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for mode in TrainMode::ALL {
            assert_eq!(mode.name().parse::<TrainMode>(), Ok(mode));
        }
        assert!("labels".parse::<TrainMode>().is_err());
    }
}
