//! What `stamp` is asked to do (`StampParams`), how it refuses (`StampError`), and the one
//! deterministic random stream per purpose, so adding a draw in one place never moves another.

use std::path::{Path, PathBuf};

use crate::scene::{DamageClass, SceneError};
use crate::synth::SynthError;

#[derive(Debug, thiserror::Error)]
pub enum StampError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Write(#[from] SynthError),
    /// The input or the parameters cannot be stamped: one line naming the file or the option.
    #[error("{}: {message}", path.display())]
    Refused { path: PathBuf, message: String },
}

impl StampError {
    pub fn refused(path: impl AsRef<Path>, message: impl Into<String>) -> StampError {
        StampError::Refused {
            path: path.as_ref().to_path_buf(),
            message: message.into(),
        }
    }
}

/// Everything that shapes a stamped dataset; the same parameters and inputs give the same bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct StampParams {
    /// The posed capture (COLMAP or transforms.json folder).
    pub capture: PathBuf,
    /// Output folder: `survey-1/` (and `survey-2/`) are written in it.
    pub out: PathBuf,
    /// Folders of real crack photos with masks (crackforest's `image/` + `masks/`, or
    /// `N.png` + `N_m.png` pairs as in the tunnel samples).
    pub crack_sources: Vec<PathBuf>,
    pub seed: u64,
    /// Metres per model unit; `None`: the capture's `georef.json`, else its photos' EXIF GPS.
    pub metres_per_unit: Option<f64>,
    /// Classes stamped (rebar is drawn inside spalls, so it needs spalling).
    pub classes: Vec<DamageClass>,
    /// Survey-1 cracks and spalls, and the ones added in survey 2.
    pub cracks: usize,
    pub spalls: usize,
    pub new_cracks: usize,
    pub new_spalls: usize,
    /// Nominal crack length (each crack draws 0.6–1.0 of it) and spall diameter, metres.
    pub crack_length_m: f64,
    pub spall_diameter_m: f64,
    /// Cracks thinner than this (mean width, metres) are widened to it: a real crack of a few
    /// millimetres is below a pixel at street distances.
    pub crack_width_m: f64,
    /// Share of a crack's length visible in survey 1 (the rest grows in by survey 2), and the
    /// factor a spall's outline grows by.
    pub crack_survey1_share: f64,
    pub spall_growth: f64,
    /// Points within this distance of a plane are its inliers (metres).
    pub plane_tolerance_m: f64,
    /// A surface is used when at least this many photos see it.
    pub min_views: usize,
    /// Number of surveys written (1 or 2).
    pub surveys: u32,
}

impl StampParams {
    /// The defaults the CLI starts from.
    pub fn new(capture: &Path, out: &Path, crack_sources: Vec<PathBuf>) -> StampParams {
        StampParams {
            capture: capture.to_path_buf(),
            out: out.to_path_buf(),
            crack_sources,
            seed: 1,
            metres_per_unit: None,
            classes: DamageClass::ALL.to_vec(),
            cracks: 6,
            spalls: 3,
            new_cracks: 2,
            new_spalls: 1,
            crack_length_m: 1.5,
            spall_diameter_m: 0.6,
            crack_width_m: 0.02,
            crack_survey1_share: 0.65,
            spall_growth: 1.3,
            plane_tolerance_m: 0.1,
            min_views: 3,
            surveys: 2,
        }
    }

    pub(crate) fn check(&self) -> Result<(), StampError> {
        let option = |name: &str, message: &str| {
            StampError::refused(&self.capture, format!("--{name}: {message}"))
        };
        if !(1..=2).contains(&self.surveys) {
            return Err(option("surveys", "must be 1 or 2"));
        }
        if self.classes.contains(&DamageClass::Rebar)
            && !self.classes.contains(&DamageClass::Spalling)
        {
            return Err(option(
                "classes",
                "rebar is exposed inside spalls: add spalling to the classes",
            ));
        }
        let positive = [
            ("crack-length-m", self.crack_length_m),
            ("spall-diameter-m", self.spall_diameter_m),
            ("crack-width-m", self.crack_width_m),
            ("plane-tolerance-m", self.plane_tolerance_m),
            ("spall-growth", self.spall_growth),
            ("crack-survey1-share", self.crack_survey1_share),
        ];
        for (name, value) in positive {
            if !(value > 0.0 && value.is_finite()) {
                return Err(option(name, "must be a positive number"));
            }
        }
        if self.crack_survey1_share > 1.0 || self.spall_growth < 1.0 {
            return Err(option(
                "crack-survey1-share / spall-growth",
                "damage only grows: share at most 1, growth at least 1",
            ));
        }
        if let Some(m) = self.metres_per_unit
            && !(m > 0.0 && m.is_finite())
        {
            return Err(option("metres-per-unit", "must be a positive number"));
        }
        if self.classes.contains(&DamageClass::Crack) && self.crack_sources.is_empty() {
            return Err(option(
                "crack-photos",
                "cracks are cut from real crack photos with masks: name a folder of them",
            ));
        }
        Ok(())
    }

    pub(crate) fn stamps(&self, class: DamageClass) -> bool {
        self.classes.contains(&class)
    }
}

/// Independent seeded streams: planes, placement, appearance and light each draw from their own.
pub(crate) fn rng(seed: u64, purpose: u64) -> fastrand::Rng {
    fastrand::Rng::with_seed(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ purpose)
}

/// Parses a comma-separated class list (`crack,spalling`), naming an unknown one.
pub fn parse_classes(text: &str) -> Result<Vec<DamageClass>, String> {
    let mut classes = Vec::new();
    for id in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let class = DamageClass::from_id(id).ok_or_else(|| {
            format!("unknown damage class {id:?} (known: crack, spalling, rebar)")
        })?;
        if !classes.contains(&class) {
            classes.push(class);
        }
    }
    if classes.is_empty() {
        return Err("no damage class given (known: crack, spalling, rebar)".into());
    }
    Ok(classes)
}
