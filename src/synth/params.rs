//! What `synth` is asked for (`SynthParams`, serialised into every manifest), what it returns
//! (`SynthOutput`) and how it fails (`SynthError`, always naming the file). No generation logic.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::scene::SceneError;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SynthParams {
    /// Output folder; `survey-1/` and `survey-2/` are created in it.
    pub out: PathBuf,
    pub seed: u64,
    pub width: u32,
    pub height: u32,
    /// Views of survey 1.
    pub views: usize,
    /// Views of survey 2.
    pub views_survey2: usize,
    /// 1 or 2.
    pub surveys: u32,
    /// Fraction of views whose written masks get random added and removed blobs.
    pub mask_noise: f32,
    /// The textureless variant: every component a flat colour.
    pub component_colours: bool,
    pub floors: u32,
    pub bays_x: u32,
    pub bays_y: u32,
    /// Sparse SfM-like points per survey.
    pub sparse_points: usize,
    pub hfov_degrees: f32,
    /// Which frame survey 2's COLMAP model is in.
    #[serde(default)]
    pub survey2_frame: Survey2Frame,
    /// What is generated. Left out of the manifest for the building, so its files stay as they
    /// were before bridges existed.
    #[serde(default, skip_serializing_if = "Structure::is_building")]
    pub structure: Structure,
}

/// The generated structure.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Structure {
    /// The RC frame building (`floors`, `bays_x`, `bays_y`).
    #[default]
    Building,
    /// A multi-span girder bridge of `spans` spans (`synth::bridge`); the building's floor and
    /// bay counts are not used.
    Bridge { spans: u32 },
}

impl Structure {
    /// The most spans a bridge may have (a 20 m span each: 1.28 km).
    pub const MAX_SPANS: u32 = 64;

    pub fn is_building(&self) -> bool {
        *self == Structure::Building
    }
}

/// The frame of survey 2's COLMAP model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Survey2Frame {
    /// Survey 1's world frame; survey 2's images only.
    #[default]
    Same,
    /// As a user's COLMAP run over old and new images would give: one model of survey 1's
    /// images and survey 2's (`new-view-NNN.png`) in a random similarity frame with pose noise.
    Joint,
}

impl Survey2Frame {
    pub const ALL: [Survey2Frame; 2] = [Survey2Frame::Same, Survey2Frame::Joint];

    pub fn name(self) -> &'static str {
        match self {
            Survey2Frame::Same => "same",
            Survey2Frame::Joint => "joint",
        }
    }
}

impl std::fmt::Display for Survey2Frame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Survey2Frame {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        Survey2Frame::ALL
            .into_iter()
            .find(|m| m.name() == text)
            .ok_or_else(|| format!("unknown survey-2 frame {text:?}: use same or joint"))
    }
}

impl SynthParams {
    /// The built-in demo: 60 + 12 views at 960×540 of a 3-storey, 4×2-bay building.
    pub fn demo(out: impl Into<PathBuf>) -> SynthParams {
        SynthParams {
            out: out.into(),
            seed: 7,
            width: 960,
            height: 540,
            views: 60,
            views_survey2: 12,
            surveys: 2,
            mask_noise: 0.0,
            component_colours: false,
            floors: 3,
            bays_x: 4,
            bays_y: 2,
            sparse_points: 30_000,
            hfov_degrees: 65.0,
            survey2_frame: Survey2Frame::Same,
            structure: Structure::Building,
        }
    }

    /// The built-in bridge of `spans` 20 m spans (the CLI's default is 6): 360 + 120 views at
    /// 960×540 (side strips at two heights on both sides and a strip under the deck).
    pub fn bridge(out: impl Into<PathBuf>, spans: u32) -> SynthParams {
        SynthParams {
            views: 360,
            views_survey2: 120,
            sparse_points: 120_000,
            structure: Structure::Bridge { spans },
            ..SynthParams::demo(out)
        }
    }

    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |m: &str| Err(SynthError::InvalidParams(m.to_string()));
        if !(self.width >= 16 && self.height >= 16 && self.width <= 8192 && self.height <= 8192) {
            return bad("width and height must be between 16 and 8192");
        }
        if self.views == 0 || (self.surveys >= 2 && self.views_survey2 == 0) {
            return bad("every survey needs at least one view");
        }
        if !(1..=2).contains(&self.surveys) {
            return bad("--surveys must be 1 or 2");
        }
        if !(self.mask_noise >= 0.0 && self.mask_noise <= 1.0) {
            return bad("--mask-noise must be a fraction in [0, 1]");
        }
        if !(1..=8).contains(&self.floors)
            || !(1..=8).contains(&self.bays_x)
            || !(1..=8).contains(&self.bays_y)
        {
            return bad("floors and bays must be between 1 and 8");
        }
        if !(self.hfov_degrees > 10.0 && self.hfov_degrees < 150.0) {
            return bad("the field of view must be between 10 and 150 degrees");
        }
        if let Structure::Bridge { spans } = self.structure
            && !(1..=Structure::MAX_SPANS).contains(&spans)
        {
            return Err(SynthError::InvalidParams(format!(
                "--spans must be between 1 and {}",
                Structure::MAX_SPANS
            )));
        }
        if self.survey2_frame == Survey2Frame::Joint && self.surveys < 2 {
            return bad("--survey2-frame joint needs --surveys 2");
        }
        Ok(())
    }
}

/// What one written survey holds.
#[derive(Clone, Debug, PartialEq)]
pub struct SurveyOutput {
    pub dir: PathBuf,
    pub views: usize,
    pub points: usize,
    /// Views with any pixel of each class in the clean masks, in `DamageClass::ALL` order.
    pub views_with_class: [usize; 3],
    /// Views whose written masks were corrupted.
    pub corrupted_views: usize,
    /// The survey's true damage totals (`truth/quantities.json`).
    pub quantities: crate::synth::quantities::Totals,
}

#[derive(Clone, Debug, PartialEq)]
pub struct SynthOutput {
    pub surveys: Vec<SurveyOutput>,
}

#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error("invalid synth parameters: {0}")]
    InvalidParams(String),
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: {source}", path.display())]
    Image {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
    #[error(transparent)]
    Scene(#[from] SceneError),
}
