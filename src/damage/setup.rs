//! A training run on a dataset in one of the three modes: which views train and which are held
//! out, at which scale, with which targets (photos, photos with damage painted on, or photos plus
//! label masks) and initial Gaussians. The CLI, the viewer, the headless demo and the mask-noise
//! study all start their runs here, so the same settings give the same run everywhere.

use std::sync::Arc;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::damage::overlay::{OVERLAY_TOLERANCE, paint_overlay, seed_class_colours};
use crate::damage::{DamageClass, Palette, TrainMode};
use crate::scene::{Dataset, ImageScale, RgbImage};
use crate::splats::Splats;
use crate::splats::model::OverlayColours;
use crate::train::job::{JobContext, JobError, JobOptions};
use crate::train::run::{TrainJob, TrainSetup, train_with};
use crate::train::spec::{DensifyPolicy, TrainSpec, TrainView, densify_for_budget};
use crate::train::views::{Holdout, InitialModel, initial_splats, load_views, split_views};

/// Random initial points of an interactive run when the dataset has none (3DGS uses 100k for
/// NeRF-synthetic; a few thousand converge faster on a CPU and densification adds the rest).
const INTERACTIVE_RANDOM_POINTS: usize = 5_000;

/// The scale a coarse twin trains at: a quarter of the 960×540 demo (240×135). At half size the
/// CPU trainer managed about one step per second on a loaded 2-core machine beside the viewer
/// (measured under Xvfb); a quarter is 4× cheaper and is the scale of docs/DAMAGE.md's figures.
/// The viewer's training resolution and `twin new`'s default.
pub const COARSE_SCALE: ImageScale = ImageScale::Factor(4);

/// The few training settings the viewer exposes (its training panel; persisted with its
/// settings). `RunConfig::interactive` turns them into a run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TrainingSettings {
    pub iterations: u32,
    /// The resolution training loads the photos at. Stored as the CLI spells it (`"4"`,
    /// `"w960"`); settings stored before it was a scale held `resolution_factor: 4`.
    #[serde(alias = "resolution_factor", with = "scale_text")]
    pub scale: ImageScale,
    pub mode: TrainMode,
    /// Weight of the label BCE loss in label mode.
    pub label_weight: f32,
    /// Most Gaussians the model may end with (`RunConfig::budget`; None: no budget).
    pub budget: Option<usize>,
}

impl Default for TrainingSettings {
    fn default() -> Self {
        TrainingSettings {
            iterations: 3000,
            scale: COARSE_SCALE,
            mode: TrainMode::Label,
            label_weight: RunConfig::default().label_weight,
            budget: None,
        }
    }
}

/// `TrainingSettings::scale` in a settings file: written as its CLI text, read from that text
/// or from the bare factor older settings stored (`resolution_factor: 4`). A text that is no
/// scale is refused; a factor that is none is read, and `Settings::sanitised` resets it.
mod scale_text {
    use serde::de::{Error, Unexpected, Visitor};
    use serde::{Deserializer, Serializer};

    use crate::scene::ImageScale;

    pub fn serialize<S: Serializer>(scale: &ImageScale, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(scale)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<ImageScale, D::Error> {
        d.deserialize_any(ScaleVisitor)
    }

    struct ScaleVisitor;

    impl Visitor<'_> for ScaleVisitor {
        type Value = ImageScale;

        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("an image scale (1, 2, 4, 8 or w<width>)")
        }

        fn visit_u64<E: Error>(self, factor: u64) -> Result<ImageScale, E> {
            u32::try_from(factor)
                .ok()
                .map(ImageScale::Factor)
                .ok_or_else(|| E::invalid_value(Unexpected::Unsigned(factor), &self))
        }

        fn visit_i64<E: Error>(self, factor: i64) -> Result<ImageScale, E> {
            u64::try_from(factor)
                .map_err(|_| E::invalid_value(Unexpected::Signed(factor), &self))
                .and_then(|f| self.visit_u64(f))
        }

        fn visit_str<E: Error>(self, text: &str) -> Result<ImageScale, E> {
            ImageScale::parse(text).ok_or_else(|| E::invalid_value(Unexpected::Str(text), &self))
        }
    }
}

/// Everything that defines a run besides the dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct RunConfig {
    pub mode: TrainMode,
    pub palette: Palette,
    pub scale: ImageScale,
    pub iterations: u32,
    pub holdout: Holdout,
    pub sh_degree: u32,
    pub seed: u64,
    pub background: Vec3,
    /// Weight of the label loss beside the photometric loss (label mode).
    pub label_weight: f32,
    /// Weight of damage pixels in the label cross-entropy (see `Targets::label_pos_weight`).
    pub label_pos_weight: f32,
    /// The fraction of the run during which the label loss shapes the geometry
    /// (`Targets::label_geometry_steps`; None: all of it).
    pub label_geometry_until: Option<f32>,
    /// Adam learning rate of the label logits (None: the optimiser's default).
    pub label_lr: Option<f32>,
    /// Random initial points when the dataset has none.
    pub random_points: usize,
    /// Held-out evaluation every this many steps (0: only at the end).
    pub eval_every: u32,
    /// Cap on the Gaussian count (None: adaptive density control as in 3DGS).
    pub max_gaussians: Option<usize>,
    /// Most Gaussians the model ends with: density control may grow past it, then the least
    /// important (least blending weight over the training views) are pruned at 3/4 of the run
    /// and training goes on (`train::spec::densify_for_budget`). Wins over
    /// `max_gaussians`.
    pub budget: Option<usize>,
    /// Learn each training photo's exposure and white balance (`train::appearance`).
    pub appearance: Option<crate::train::appearance::AppearanceConfig>,
    /// Overlay mode: paint the damage in colours chosen against the training photos
    /// (`Palette::contrasting`) instead of `palette`.
    pub contrasting_palette: bool,
    /// The renderer the run trains on.
    pub backend: crate::train::backend_choice::Backend,
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            mode: TrainMode::Label,
            palette: Palette::default(),
            scale: ImageScale::Factor(1),
            iterations: 7000,
            holdout: Holdout::Auto { every: 8 },
            sh_degree: 3,
            seed: 0,
            background: Vec3::ZERO,
            // docs/DAMAGE.md: against 0.1 and 0.3, a weight of 1 raised the held-out crack IoU
            // of the demo building from 0.60 and 0.67 to 0.71 (3,000 steps), for 0.6 dB of PSNR.
            label_weight: 1.0,
            // Measured on the demo building (docs/DAMAGE.md): against 1.0 and the optimiser's
            // 0.01, these doubled the held-out crack IoU (0.19 → 0.41) in about half the steps.
            label_pos_weight: 4.0,
            label_geometry_until: None,
            label_lr: Some(0.05),
            random_points: 100_000,
            eval_every: 0,
            max_gaussians: None,
            budget: None,
            appearance: None,
            // docs/DAMAGE.md: the default pink of spalling is within 70 of the demo's sunlit
            // plaster, so a tolerance that keeps blended edges reads the walls as spalling.
            contrasting_palette: true,
            backend: Default::default(),
        }
    }
}

impl RunConfig {
    /// The run the viewer's training settings describe (and the headless demo, which runs what
    /// the viewer runs): every-8th held-out rule, ten held-out evaluations for the PSNR chart,
    /// the damage layer's colours as the overlay palette.
    pub fn interactive(
        settings: &TrainingSettings,
        palette: Palette,
        background: [f32; 3],
    ) -> RunConfig {
        RunConfig {
            mode: settings.mode,
            palette,
            scale: settings.scale,
            iterations: settings.iterations.max(1),
            holdout: Holdout::Auto { every: 8 },
            background: Vec3::from_array(background),
            label_weight: settings.label_weight,
            random_points: INTERACTIVE_RANDOM_POINTS,
            eval_every: (settings.iterations / 10).max(1),
            budget: settings.budget,
            ..RunConfig::default()
        }
    }
}

/// Starts training `config` on `dataset`: the views are loaded and the model initialised on the
/// worker, and what was decided on the way (mode fallback, counts) goes to the job's log.
pub fn train_job(dataset: Arc<Dataset>, config: RunConfig, options: JobOptions) -> TrainJob {
    train_with(
        move |ctx: &mut JobContext| {
            let run = prepare_run(&dataset, &config)?;
            for note in run.notes {
                ctx.log(note);
            }
            Ok(run.setup)
        },
        options,
    )
}

/// A prepared run and what was decided on the way.
pub struct PreparedRun {
    pub setup: TrainSetup,
    /// The mode actually used (RGB when a damage mode was asked for on a dataset without masks).
    pub mode: TrainMode,
    /// Indices in `dataset.views` of the training and held-out views.
    pub train_indices: Vec<usize>,
    pub heldout_indices: Vec<usize>,
    /// Things the user should know (falling back to RGB, counts), one line each.
    pub notes: Vec<String>,
}

/// The mode a dataset supports: damage modes need masks.
pub fn effective_mode(dataset: &Dataset, mode: TrainMode) -> TrainMode {
    let has_masks = dataset.mask_counts.values().any(|&n| n > 0);
    if mode.uses_masks() && !has_masks {
        TrainMode::Rgb
    } else {
        mode
    }
}

/// Loads the views and builds the initial model and spec for `config` on `dataset`.
pub fn prepare_run(dataset: &Dataset, config: &RunConfig) -> Result<PreparedRun, JobError> {
    let mut notes = Vec::new();
    let mode = effective_mode(dataset, config.mode);
    if mode != config.mode {
        notes.push(format!(
            "no damage masks in {}: training RGB only instead of {} mode",
            dataset.root.display(),
            config.mode
        ));
    }
    let (train_indices, heldout_indices) =
        split_views(dataset, &config.holdout).map_err(JobError::Invalid)?;
    let labels = mode.uses_masks();
    let mut views = load_views(dataset, &train_indices, config.scale, labels)?;
    let mut heldout = load_views(dataset, &heldout_indices, config.scale, labels)?;
    let overlay = overlay_colours(&views, config, mode);
    if let Some(o) = &overlay {
        let rgb = |c: [u8; 3]| format!("{},{},{}", c[0], c[1], c[2]);
        notes.push(format!(
            "overlay colours: crack {}, spalling {}, rebar {}; read back within {:.0}",
            rgb(o.colours[0]),
            rgb(o.colours[1]),
            rgb(o.colours[2]),
            o.tolerance
        ));
    }
    // The initial model needs only the views' cameras; overlay mode seeds its colours from the
    // masks before they are painted in.
    let (mut splats, spec) = model_and_spec(dataset, &views, config, mode)?;
    let palette = overlay
        .as_ref()
        .map_or(config.palette, Palette::from_overlay);
    let seeded = prepare_targets(&mut views, &mut splats, mode, overlay, &palette);
    apply_mode(&mut heldout, mode, &palette);
    if mode == TrainMode::Overlay {
        notes.push(format!("{seeded} Gaussians start in a class colour"));
    }
    notes.push(format!(
        "{} training and {} held-out views at {}×{}, {} initial Gaussians, {mode} mode",
        views.len(),
        heldout.len(),
        views[0].image.width,
        views[0].image.height,
        splats.len()
    ));
    Ok(PreparedRun {
        setup: TrainSetup {
            spec,
            splats,
            views,
            heldout,
        },
        mode,
        train_indices,
        heldout_indices,
        notes,
    })
}

/// The initial Gaussians (with label channels in label mode) and the run's spec, for training
/// views already prepared for `mode`.
pub fn model_and_spec(
    dataset: &Dataset,
    views: &[TrainView],
    config: &RunConfig,
    mode: TrainMode,
) -> Result<(Splats, TrainSpec), JobError> {
    let init = InitialModel {
        sh_degree: config.sh_degree,
        label_channels: label_channels(mode),
        random_points: config.random_points,
        seed: config.seed,
    };
    let splats = initial_splats(dataset, views, &init)?;
    Ok((splats, run_spec(config, mode)))
}

/// Damage label channels a model trained in `mode` carries.
fn label_channels(mode: TrainMode) -> usize {
    if mode == TrainMode::Label {
        DamageClass::ALL.len()
    } else {
        0
    }
}

/// The spec of a run of `config` in `mode` (`model_and_spec`'s, for a run that starts from a
/// model of its own rather than the initial one).
pub fn run_spec(config: &RunConfig, mode: TrainMode) -> TrainSpec {
    let mut spec = TrainSpec::reconstruction(config.iterations.max(1));
    spec.sh_degree = config.sh_degree;
    spec.seed = config.seed;
    spec.background = config.background;
    spec.eval_every = config.eval_every;
    spec.appearance = config.appearance;
    spec.backend = config.backend;
    spec.targets.label_weight = if label_channels(mode) > 0 {
        config.label_weight
    } else {
        0.0
    };
    spec.targets.label_pos_weight = config.label_pos_weight;
    spec.targets.label_geometry_steps =
        geometry_steps(config.label_geometry_until, spec.iterations);
    spec.lr.raw_labels = config.label_lr;
    if let Some(max) = config.max_gaussians {
        spec.densify = DensifyPolicy::Budget { max };
    }
    if let Some(budget) = config.budget {
        spec.densify = DensifyPolicy::Adaptive(densify_for_budget(spec.iterations, budget, 0));
    }
    spec
}

/// `Targets::label_geometry_steps` for the fraction `until` of a run of `iterations` steps.
pub fn geometry_steps(until: Option<f32>, iterations: u32) -> Option<u32> {
    until.map(|f| (f.clamp(0.0, 1.0) * iterations as f32).round() as u32)
}

/// The colours an overlay-mode run paints its damage in (None in other modes): chosen against
/// the training photos (`views`, before painting) when `config.contrasting_palette`, else
/// `config.palette` with the readout's default tolerance. They are saved with the model.
pub fn overlay_colours(
    views: &[TrainView],
    config: &RunConfig,
    mode: TrainMode,
) -> Option<OverlayColours> {
    if mode != TrainMode::Overlay {
        return None;
    }
    Some(if config.contrasting_palette {
        let photos: Vec<&RgbImage> = views.iter().map(|v| &v.image).collect();
        Palette::contrasting(&photos)
    } else {
        OverlayColours {
            colours: config.palette.colours,
            tolerance: OVERLAY_TOLERANCE,
        }
    })
}

/// Turns training views loaded with their label masks into the targets of `mode` for `splats`,
/// the run's initial model: in overlay mode its Gaussians on painted damage start in their
/// class colour (`seed_class_colours`) and it carries `overlay`, then the masks are painted in
/// (`apply_mode`). Returns how many Gaussians were seeded.
pub fn prepare_targets(
    views: &mut [TrainView],
    splats: &mut Splats,
    mode: TrainMode,
    overlay: Option<OverlayColours>,
    palette: &Palette,
) -> usize {
    let seeded = if mode == TrainMode::Overlay {
        seed_class_colours(splats, views, palette)
    } else {
        0
    };
    splats.overlay = overlay;
    apply_mode(views, mode, palette);
    seeded
}

/// Turns views loaded with their label masks into the targets of `mode`: overlay paints the
/// masks into the photo and drops them; label keeps them; RGB drops them.
pub fn apply_mode(views: &mut [TrainView], mode: TrainMode, palette: &Palette) {
    for view in views {
        match mode {
            TrainMode::Overlay => {
                paint_overlay(&mut view.image, &view.labels, palette);
                view.labels.clear();
            }
            TrainMode::Rgb => view.labels.clear(),
            TrainMode::Label => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_training_scale_is_stored_as_text_and_read_from_an_older_factor() {
        let settings = TrainingSettings {
            scale: ImageScale::Width(960),
            ..TrainingSettings::default()
        };
        let text = ron::to_string(&settings).expect("serialises");
        assert!(text.contains("scale:\"w960\""), "{text}");
        assert_eq!(
            ron::from_str::<TrainingSettings>(&text).expect("parses"),
            settings
        );
        let older: TrainingSettings =
            ron::from_str("(iterations: 3000, resolution_factor: 2)").expect("parses");
        assert_eq!(older.scale, ImageScale::Factor(2));
        assert!(ron::from_str::<TrainingSettings>("(scale: \"3\")").is_err());
    }
}
