//! Change detection of one survey of a project, as `twin detect` and the viewer run it: the
//! model of the latest earlier survey that has one, rendered at the survey's poses against its
//! masks (`changes::detect`), written as change maps (`surveys/<name>/changes/<view>.png`: old
//! damage in its class colour, new damage in the new-damage colour, damage no longer seen in
//! cyan) and `changes.json`, and recorded in the project.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::damage::evaluate::DamageReadout;
use crate::damage::{DamageClass, Palette};
use crate::raster::RenderSettings;
use crate::scene::ImageScale;
use crate::scene::atomic::write_atomic;
use crate::timeline::blocks::changed::{BlockChanges, changes_per_block};
use crate::timeline::blocks::load_survey_blocks;
use crate::timeline::changes::{
    DetectConfig, OLD_DAMAGE_THRESHOLD, StepScores, change_picture, detect,
};
use crate::timeline::earlier::EarlierSurvey;
use crate::timeline::twin::{TimelineError, Twin};
use crate::train::job::{Job, JobError, JobOptions, Progress};

/// The name of the change maps' folder inside a survey's folder, and of its summary.
pub const CHANGES_DIR: &str = "changes";
pub const CHANGES_FILE: &str = "changes.json";

/// The default tolerance band: on the demo it removes the thin slivers a registered survey
/// leaves along old cracks (joint-frame crack precision 0.764 → 0.957) at a cost of under 0.011
/// recall per class (docs/TIMELINE.md, "Detection, measured").
pub const DEFAULT_BAND_PX: u32 = 1;

/// How changes are found (the CLI's flags; docs/TIMELINE.md measures each).
#[derive(Clone, Debug, PartialEq)]
pub struct DetectOptions {
    /// The resolution changes are found at.
    pub scale: ImageScale,
    /// New blobs wholly within this many pixels of old damage of their class are not new.
    pub band_px: u32,
    /// New-damage blobs smaller than this many pixels are dropped.
    pub min_area_px: usize,
    /// Also drop candidates the earlier survey's own masks show at the same surface point.
    pub earlier: bool,
    /// Earlier-survey check: mask pixels this close to a candidate's surface point count.
    pub earlier_radius: u32,
    /// Keep only candidates the views agree on in 3D.
    pub vote: bool,
    /// Label mode: the class probability above which the twin's render is old damage.
    pub old_threshold: f32,
}

impl Default for DetectOptions {
    fn default() -> Self {
        DetectOptions {
            scale: ImageScale::Factor(2),
            band_px: DEFAULT_BAND_PX,
            min_area_px: 0,
            earlier: false,
            earlier_radius: 2,
            vote: false,
            old_threshold: OLD_DAMAGE_THRESHOLD,
        }
    }
}

/// New damage of one class after the last cleaning step, scored where the survey has truth.
#[derive(Clone, Debug, Serialize)]
pub struct ClassFigures {
    pub pixels: u64,
    pub truth_pixels: Option<u64>,
    pub precision: Option<f64>,
    pub recall: Option<f64>,
    pub f1: Option<f64>,
    pub iou: Option<f64>,
}

/// What `changes.json` holds.
#[derive(Clone, Debug, Serialize)]
pub struct ChangeSummary {
    pub survey: String,
    /// The survey whose model was compared with.
    pub twin_of: String,
    pub scale: ImageScale,
    pub views: usize,
    pub new_damage: BTreeMap<String, ClassFigures>,
    /// The same figures after each cleaning step: raw, band, area, earlier, vote.
    pub steps: Vec<StepScores>,
    /// On a partitioned twin (`twin_of`'s model merged from a block plan), the changed pixels
    /// per block (`timeline::blocks::changed`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub blocks: Option<BlockChanges>,
    /// The change maps' folder.
    #[serde(skip)]
    pub folder: PathBuf,
}

/// The latest survey before `index` that has a model.
pub fn compared_survey(twin: &Twin, index: usize) -> Option<String> {
    twin.project.surveys[..index.min(twin.project.surveys.len())]
        .iter()
        .rev()
        .find(|s| s.model.is_some())
        .map(|s| s.name.clone())
}

fn io(path: &Path, message: impl std::fmt::Display) -> TimelineError {
    TimelineError::Io {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// Detects survey `name`'s changes against the twin before it, then writes the change maps and
/// `changes.json` and records the folder in the project as one commit, under the project's lock. `on_view(done, total)`
/// reports progress.
pub fn detect_survey(
    twin: &mut Twin,
    name: &str,
    options: &DetectOptions,
    on_view: &mut dyn FnMut(usize, usize),
) -> Result<ChangeSummary, TimelineError> {
    let index = twin.survey_index(name)?;
    let previous = compared_survey(twin, index).ok_or_else(|| {
        io(
            &twin.file(),
            format!("no survey before `{name}` has a model to compare with"),
        )
    })?;
    let model = twin
        .load_model(&previous)?
        .ok_or_else(|| io(&twin.file(), format!("survey `{previous}` has no model")))?;
    let dataset = twin.open_survey_dataset(name)?;
    let palette = Palette {
        colours: DamageClass::ALL.map(|c| twin.project.colour(c)),
    };
    let config = DetectConfig {
        scale: options.scale,
        readout: DamageReadout::for_model(&model, palette),
        background: glam::Vec3::from_array(twin.project.settings.background),
        band_px: options.band_px,
        min_area_px: options.min_area_px,
        vote: options.vote,
        old_threshold: options.old_threshold,
    };
    let earlier = if options.earlier {
        let settings = RenderSettings::new(config.background, model.sh_degree);
        let earlier_dataset = twin.open_survey_dataset(&previous)?;
        Some(EarlierSurvey::load(
            &model,
            &earlier_dataset,
            options.scale,
            &settings,
            options.earlier_radius,
        )?)
    } else {
        None
    };
    let detection = detect(&model, &dataset, &config, earlier.as_ref(), on_view)?;
    let blocks = match load_survey_blocks(twin, &previous)? {
        Some(record) => {
            let plan = crate::blocks::load_plan(&record.plan)?;
            Some(changes_per_block(
                &plan,
                &model,
                &dataset,
                &detection.views,
                options.scale,
                config.background,
            )?)
        }
        None => None,
    };
    // The pictures are made before the lock is taken; the lock is held only to write them.
    let mut pictures = Vec::with_capacity(detection.views.len());
    for view in &detection.views {
        let photo = dataset.load_view(view.index, options.scale)?;
        let picture = change_picture(
            view,
            &photo.image,
            &palette.colours,
            twin.project.settings.new_damage_colour,
        );
        pictures.push((view.name.clone(), picture));
    }
    let last = detection.summary().cloned().unwrap_or_default();
    let new_damage = last
        .pixels
        .iter()
        .map(|(class, &pixels)| {
            let figure = ClassFigures {
                pixels,
                truth_pixels: last.truth_pixels.get(class).copied(),
                precision: last.precision.get(class).copied(),
                recall: last.recall.get(class).copied(),
                f1: last.f1.get(class).copied(),
                iou: last.iou.get(class).copied(),
            };
            (class.clone(), figure)
        })
        .collect();
    let folder = twin.survey_file(name, CHANGES_DIR)?;
    let summary = ChangeSummary {
        survey: name.to_string(),
        twin_of: previous,
        scale: options.scale,
        views: detection.views.len(),
        new_damage,
        steps: detection.steps,
        blocks,
        folder: folder.clone(),
    };
    let json = serde_json::to_string_pretty(&summary)
        .map_err(|e| io(&folder, format!("cannot serialise the summary: {e}")))?;
    // One commit: the maps and `changes.json` replace the previous detection's (none of which
    // stays) together with the record naming them, or nothing changes.
    twin.commit(|twin| {
        let staged = twin.output_path(name, CHANGES_DIR)?;
        std::fs::create_dir_all(&staged).map_err(|e| io(&staged, e))?;
        for (view, picture) in &pictures {
            crate::damage::display::save_png(&change_map_path(&staged, view), picture)?;
        }
        let path = staged.join(CHANGES_FILE);
        write_atomic(&path, |w| std::io::Write::write_all(w, json.as_bytes()))?;
        set_changes(twin, name, &folder)
    })?;
    Ok(summary)
}

/// Records `folder` as survey `name`'s change maps, as one commit (`Twin::commit`): only that
/// survey's record changes in the project as it is now, so whatever another command recorded
/// while the detection ran stays.
pub fn record_changes(twin: &mut Twin, name: &str, folder: &Path) -> Result<(), TimelineError> {
    twin.commit(|twin| set_changes(twin, name, folder))
}

fn set_changes(twin: &mut Twin, name: &str, folder: &Path) -> Result<(), TimelineError> {
    let index = twin.survey_index(name)?;
    twin.project.surveys[index].changes = Some(twin.relative(folder));
    Ok(())
}

/// `detect_survey` as a job (the viewer's "detect changes"): progress per view; the project as
/// saved afterwards comes back with the summary.
pub fn detect_job(
    mut twin: Twin,
    name: String,
    options: DetectOptions,
    job: JobOptions,
) -> Job<(Twin, ChangeSummary)> {
    Job::spawn("detect", job, move |ctx| {
        let started = std::time::Instant::now();
        let summary = detect_survey(&mut twin, &name, &options, &mut |done, total| {
            let elapsed = started.elapsed();
            let eta = elapsed.mul_f64((total - done) as f64 / done.max(1) as f64);
            ctx.progress(Progress {
                phase: "detect",
                step: done as u32,
                total: total as u32,
                loss: f32::NAN,
                psnr: None,
                gaussians: 0,
                elapsed,
                eta,
            });
        })
        .map_err(JobError::other)?;
        Ok((twin, summary))
    })
}

/// The change map of view `view_name` in a changes folder (`/` in a view name becomes `_`).
pub fn change_map_path(folder: &Path, view_name: &str) -> PathBuf {
    folder.join(format!("{}.png", view_name.replace('/', "_")))
}
