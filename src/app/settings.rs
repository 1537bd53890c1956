//! The viewer's persisted settings (eframe storage, RON): view, navigation, training defaults and
//! the damage layer. Plain data with serde defaults, so an older or partial file still loads;
//! no UI and no I/O beyond the storage hand-off.

use serde::{Deserialize, Serialize};

use crate::app::camera_controller::NavMode;

/// Key under which the settings live in eframe's storage.
pub const STORAGE_KEY: &str = "damage-twin.settings";

/// What the trainer optimises (issue 7: the viewer picks the mode).
pub use crate::damage::TrainMode;

/// The damage layer's display settings (`damage::layer`).
pub use crate::damage::layer::DamageLayer;

/// The training panel's settings (`damage::setup`).
pub use crate::damage::setup::TrainingSettings;

/// How the photo of a snapped survey view is compared with the render.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum CompareMode {
    /// A vertical split: photo left of the handle, render right.
    #[default]
    Swipe,
    /// The photo drawn over the render with an opacity.
    Blend,
    /// Photo and render side by side.
    SideBySide,
}

/// How two surveys are compared in the viewport (the same camera drives both).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum SurveyLayout {
    /// Two viewports: the compared survey left, the one shown right.
    #[default]
    SideBySide,
    /// One viewport split by a handle: the compared survey left of it, the one shown right.
    Swipe,
}

/// Which renderer draws the splats in the viewport.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum ViewportRenderer {
    /// The GPU pass on a hardware adapter; the CPU worker on a software driver (docs/APP.md).
    #[default]
    Auto,
    /// The WGSL forward pass, drawn through the paint callback.
    Gpu,
    /// The CPU reference rasterizer on a worker thread.
    Cpu,
}

/// Everything the viewer remembers between runs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Settings {
    /// Background colour of the render (linear RGB in [0, 1]).
    pub background: [f32; 3],
    /// Multiplier on every Gaussian's scale when viewing (1 = as trained).
    pub splat_scale: f32,
    /// Vertical field of view of the free camera, degrees.
    pub fov_deg: f32,
    pub nav_mode: NavMode,
    /// Fly speed multiplier on the scene-derived speed.
    pub fly_speed: f32,
    pub show_grid: bool,
    pub show_frusta: bool,
    /// Orbit slowly around the target (presentations; also how frame times are measured).
    pub turntable: bool,
    /// Lower the render resolution while the camera moves.
    pub adaptive_resolution: bool,
    /// Frame time the adaptive resolution aims for, milliseconds.
    pub target_frame_ms: f32,
    /// Smallest render scale the adaptive resolution may pick.
    pub min_render_scale: f32,
    pub viewport_renderer: ViewportRenderer,
    pub compare_mode: CompareMode,
    /// How two surveys are compared.
    pub survey_layout: SurveyLayout,
    /// Photos compared with the render show their ignore mask (ignored pixels dimmed, magenta).
    pub show_ignore_masks: bool,
    /// Photos compared with the render show their damage masks or the segmenter's
    /// probabilities (docs/MASKS.md).
    pub photo_damage: crate::app::photo_damage::PhotoDamage,
    /// Photo opacity in blend mode.
    pub compare_blend: f32,
    pub training: TrainingSettings,
    pub damage: DamageLayer,
    /// Show the charts panel.
    pub show_charts: bool,
    /// Screen selections take only the Gaussians that draw inside the shape (by rendered
    /// contribution); off: every Gaussian whose centre projects inside, straight through.
    pub selection_front_most: bool,
    /// Eyedropper: largest RGB distance (0–1 per channel) of a matching base colour.
    pub colour_match: f32,
    /// Sphere radius / box half-size of the volume tools, in model units.
    pub volume_radius: f32,
    /// Most recently opened datasets / projects, newest first.
    pub recent: Vec<std::path::PathBuf>,
    /// Format of the stored settings; files written before versions existed read as 0.
    #[serde(default = "unversioned")]
    pub version: u32,
}

/// Version of the settings this build writes. 1: the label loss default went from 0.1 to 1.
const SETTINGS_VERSION: u32 = 1;

/// The version of a settings file that names none.
fn unversioned() -> u32 {
    0
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            background: [0.0, 0.0, 0.0],
            splat_scale: 1.0,
            fov_deg: 50.0,
            nav_mode: NavMode::Orbit,
            fly_speed: 1.0,
            show_grid: true,
            show_frusta: true,
            turntable: false,
            adaptive_resolution: true,
            target_frame_ms: 40.0,
            min_render_scale: 0.25,
            viewport_renderer: ViewportRenderer::Auto,
            compare_mode: CompareMode::Swipe,
            survey_layout: SurveyLayout::SideBySide,
            show_ignore_masks: true,
            photo_damage: crate::app::photo_damage::PhotoDamage::Off,
            compare_blend: 0.5,
            training: TrainingSettings::default(),
            damage: DamageLayer::default(),
            show_charts: true,
            selection_front_most: false,
            colour_match: 0.12,
            volume_radius: 0.5,
            recent: Vec::new(),
            version: SETTINGS_VERSION,
        }
    }
}

impl Settings {
    const MAX_RECENT: usize = 8;

    /// Clamps every value into its valid range (a hand-edited or corrupt file must not crash).
    pub fn sanitised(mut self) -> Settings {
        let d = Settings::default();
        for c in &mut self.background {
            *c = if c.is_finite() {
                c.clamp(0.0, 1.0)
            } else {
                0.0
            };
        }
        let clamp = |v: f32, lo: f32, hi: f32, default: f32| {
            if v.is_finite() {
                v.clamp(lo, hi)
            } else {
                default
            }
        };
        self.splat_scale = clamp(self.splat_scale, 0.01, 4.0, d.splat_scale);
        self.fov_deg = clamp(self.fov_deg, 10.0, 120.0, d.fov_deg);
        self.fly_speed = clamp(self.fly_speed, 0.01, 100.0, d.fly_speed);
        self.target_frame_ms = clamp(self.target_frame_ms, 5.0, 500.0, d.target_frame_ms);
        self.min_render_scale = clamp(self.min_render_scale, 0.1, 1.0, d.min_render_scale);
        self.compare_blend = clamp(self.compare_blend, 0.0, 1.0, d.compare_blend);
        self.damage.opacity = clamp(self.damage.opacity, 0.0, 1.0, d.damage.opacity);
        self.training.iterations = self.training.iterations.clamp(1, 1_000_000);
        if !self.training.scale.is_valid() {
            self.training.scale = crate::scene::ImageScale::Factor(1);
        }
        self.training.budget = self.training.budget.map(|n| n.clamp(1, 10_000_000));
        self.training.label_weight = clamp(
            self.training.label_weight,
            0.0,
            10.0,
            d.training.label_weight,
        );
        self.colour_match = clamp(self.colour_match, 0.0, 1.8, d.colour_match);
        self.volume_radius = clamp(self.volume_radius, 1e-3, 1e4, d.volume_radius);
        self.colour_match = clamp(self.colour_match, 0.0, 1.8, d.colour_match);
        self.volume_radius = clamp(self.volume_radius, 1e-3, 1e4, d.volume_radius);
        self.recent.truncate(Self::MAX_RECENT);
        self
    }

    /// How a still of the current view is drawn (export, as displayed).
    pub fn display_style(&self) -> crate::damage::display::DisplayStyle {
        crate::damage::display::DisplayStyle {
            background: glam::Vec3::from_array(self.background),
            splat_scale: self.splat_scale,
            damage: self.damage.clone(),
        }
    }

    /// Puts `path` first in the recent list.
    pub fn remember(&mut self, path: &std::path::Path) {
        self.recent.retain(|p| p != path);
        self.recent.insert(0, path.to_path_buf());
        self.recent.truncate(Self::MAX_RECENT);
    }

    /// Serialised form (what eframe's storage keeps).
    pub fn to_ron(&self) -> Result<String, ron::Error> {
        ron::to_string(self)
    }

    /// Parses a stored form; unknown or missing fields fall back to defaults, and older
    /// versions are brought up to this one.
    pub fn from_ron(text: &str) -> Result<Settings, ron::error::SpannedError> {
        ron::from_str::<Settings>(text)
            .map(Settings::migrated)
            .map(Settings::sanitised)
    }

    /// Brings settings stored by an older build up to [`SETTINGS_VERSION`]. Every viewer before
    /// version 1 stored the label weight whether or not the user touched it, so its old default
    /// (0.1) stands for "the default" and becomes the new one; any other value was chosen and
    /// stays.
    fn migrated(mut self) -> Settings {
        if self.version < 1 && self.training.label_weight == 0.1 {
            self.training.label_weight = TrainingSettings::default().label_weight;
        }
        self.version = SETTINGS_VERSION;
        self
    }

    /// Loads from eframe storage, defaults when absent or unreadable.
    pub fn load(storage: Option<&dyn eframe::Storage>) -> Settings {
        storage
            .and_then(|s| s.get_string(STORAGE_KEY))
            .and_then(|text| Settings::from_ron(&text).ok())
            .unwrap_or_default()
    }

    pub fn save(&self, storage: &mut dyn eframe::Storage) {
        if let Ok(text) = self.to_ron() {
            storage.set_string(STORAGE_KEY, text);
        }
    }
}
