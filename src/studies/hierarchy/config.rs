//! The hierarchy study's settings: the four methods and what each runs with.

use serde::{Deserialize, Serialize};

use crate::damage::Palette;
use crate::damage::refine::RefineConfig;
use crate::damage::setup::RunConfig;
use crate::scene::ImageScale;

/// The four methods.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    Full,
    Coarse,
    Finetune,
    Retrain,
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::Full => "full",
            Method::Coarse => "coarse",
            Method::Finetune => "finetune",
            Method::Retrain => "retrain",
        }
    }
}

/// The study's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct HierarchyConfig {
    /// The run every method starts from (mode, palette, held-out rule, seed, background); its
    /// scale and iterations are replaced per method.
    pub run: RunConfig,
    pub coarse_scale: ImageScale,
    pub coarse_iterations: u32,
    /// "High resolution": where the full run trains, refinements refine and everything is
    /// scored.
    pub fine_scale: ImageScale,
    pub full_iterations: u32,
    pub refine: RefineConfig,
    pub methods: Vec<Method>,
}

/// The study's default settings on the demo building (960×540): a 240×135 coarse twin of 3000
/// steps, 1000 refinement steps at 960×540, and a 960×540 full run of 3000 steps.
pub fn default_config(palette: Palette) -> HierarchyConfig {
    HierarchyConfig {
        run: RunConfig {
            palette,
            ..RunConfig::default()
        },
        coarse_scale: ImageScale::Factor(4),
        coarse_iterations: 3000,
        fine_scale: ImageScale::Factor(1),
        full_iterations: 3000,
        refine: RefineConfig::default(),
        methods: vec![
            Method::Coarse,
            Method::Finetune,
            Method::Retrain,
            Method::Full,
        ],
    }
}
