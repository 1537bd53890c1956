//! `pose`: a folder of photos to a posed dataset, COLMAP doing the structure from motion.
//!
//! The dataset is staged beside its target (`scene::run_folder`) and put in its place only when
//! complete, so a failure or a kill never leaves a folder that looks like a dataset:
//!
//! ```text
//! DATASET/images/…            the registered photos, as taken (hard links or copies)
//! DATASET/masks/…             the masks found beside the photos, as they were
//! DATASET/sparse/0/*.bin      COLMAP's largest registered component (SIMPLE_RADIAL camera)
//! DATASET/colmap/             COLMAP's database, every component it made, and colmap.log
//! DATASET/pose.json           what ran and what came of it (PoseSummary)
//! DATASET/georef.json         SfM frame → metres east/north/up, from control points when
//!                             given (`control_points.json`: every point's residual), else GPS
//! ```
//!
//! Undistortion: the camera keeps COLMAP's lens model and `Dataset::open` / `load_view` remove
//! it on load with one map for the photo and every mask of the view (`scene::undistort`), so the
//! masks beside the photos need no second resampling and stay exactly as drawn.

use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use glam::DVec3;
use serde::Serialize;

use crate::scene::SceneError;
use crate::scene::atomic::write_atomic;
use crate::scene::colmap::{self, ColmapModel};
use crate::scene::run_folder::RunFolder;
use crate::scene::sfm::SfmError;
use crate::scene::sfm::control::{
    CONTROL_FIT_FILE, ControlFit, fit_control_points, read_control_points,
};
use crate::scene::sfm::draws::{GPS_PLAUSIBLE_FRACTION, MapperDraw, choose_draw};
use crate::scene::sfm::engine::{Colmap, Engine};
use crate::scene::sfm::exif::{PhotoExif, read_photo_exif};
use crate::scene::sfm::georef::{GeorefSource, Georeference, fit_gps};
use crate::scene::sfm::progress::{Progress, Stage};
use crate::scene::sfm::workspace::{
    check_target, copy_masks, extract_args, failed_log_path, file_name, focal_prior,
    keep_failed_log, link_or_copy, list_photos, mean_error, read_components,
    write_summary_and_commit,
};

/// How image pairs are chosen for matching.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Matching {
    /// Every pair: best for small sets (cost grows with the square of the count).
    Exhaustive,
    /// Each photo with the next ones in file-name order: drone strips, walks along a street.
    Sequential,
    /// Each photo with its nearest neighbours by EXIF GPS position.
    Spatial,
}

impl Matching {
    /// The default for `photos` photos: exhaustive up to `EXHAUSTIVE_UP_TO`, then sequential
    /// (photos in capture order, as drones and walks take them). On lund's 29 photos sequential
    /// matching with an overlap of 10 looks at about as many pairs as exhaustive and is what
    /// was measured (docs/POSE.md); spatial matching is a choice (`--matching spatial`), since
    /// phone GPS good to 10 m finds no closer neighbours than the file order does.
    pub fn default_for(photos: usize) -> Matching {
        if photos <= EXHAUSTIVE_UP_TO {
            Matching::Exhaustive
        } else {
            Matching::Sequential
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Matching::Exhaustive => "exhaustive",
            Matching::Sequential => "sequential",
            Matching::Spatial => "spatial",
        }
    }
}

/// Photos up to which every pair is matched by default.
pub const EXHAUSTIVE_UP_TO: usize = 20;

/// Settings of a `pose` run.
#[derive(Clone, Debug)]
pub struct PoseOptions {
    /// `None`: `Matching::default_for` the set.
    pub matching: Option<Matching>,
    /// CPU threads COLMAP may use.
    pub threads: usize,
    /// SIFT features per photo (COLMAP's default is 8192; fewer matches faster).
    pub max_features: usize,
    /// Photos each photo is matched with in sequential matching.
    pub sequential_overlap: usize,
    /// Surveyed control points (`control`): their fit replaces the GPS georeference.
    pub control_points: Option<PathBuf>,
    /// Set by another thread (the app's Cancel) to stop the run: COLMAP is killed, nothing is
    /// written, and the run returns `SfmError::Cancelled`.
    pub cancel: Option<Arc<AtomicBool>>,
    /// The engine; `None`: `Engine::default_choice()` (the one measured best, docs/POSE.md).
    pub engine: Option<Engine>,
}

impl Default for PoseOptions {
    fn default() -> Self {
        PoseOptions {
            matching: None,
            threads: std::thread::available_parallelism().map_or(2, |n| n.get()),
            max_features: 8192,
            sequential_overlap: 10,
            control_points: None,
            cancel: None,
            engine: None,
        }
    }
}

impl PoseOptions {
    /// The engine to run: the one chosen, else the default.
    pub fn engine(&self) -> Engine {
        self.engine.unwrap_or_else(Engine::default_choice)
    }
}

/// What a `pose` run did, written as `pose.json` in the dataset.
#[derive(Clone, Debug, Serialize)]
pub struct PoseSummary {
    pub engine: String,
    pub matching: Matching,
    pub photos: usize,
    /// Photos in the chosen (largest) component, and the ones left out of it.
    pub registered: Vec<String>,
    pub unregistered: Vec<String>,
    /// Registered photos of every component COLMAP made, largest first.
    pub components: Vec<usize>,
    pub points: usize,
    /// Mean reprojection error of the chosen component's points, pixels.
    pub mean_reprojection_error_px: f64,
    pub georeference: Option<Georeference>,
    /// The control-point fit with every point's residual, when control points were given.
    pub control_points: Option<ControlFit>,
    /// Why the dataset has no georeference, when it has none.
    pub georeference_note: Option<String>,
    /// Every mapper draw (seed, registered photos, GPS residual), in the order run.
    pub mapper_draws: Vec<MapperDraw>,
    /// The seed of the draw kept (`draws::choose_draw`).
    pub chosen_seed: Option<u64>,
    /// Whether the kept draw's GPS residual is plausible for a right model
    /// (`draws::GPS_PLAUSIBLE_FRACTION` of the GPS baseline); `None` without a GPS fit. `false`
    /// comes with a warning: every draw may be wrong.
    pub gps_plausible: Option<bool>,
    pub seconds: f64,
    /// Things the user should know (photos without EXIF, masks not used for matching).
    pub warnings: Vec<String>,
}

/// The dataset's summary file.
pub const SUMMARY_FILE: &str = "pose.json";
/// COLMAP's log inside the dataset.
pub const LOG_FILE: &str = "colmap/colmap.log";

/// Runs COLMAP on the photos in `photos` (not its sub-folders) and writes the dataset `out`,
/// which must not exist yet or be an empty folder. `progress` is called from COLMAP's output.
pub fn pose_photos(
    photos: &Path,
    out: &Path,
    options: &PoseOptions,
    progress: &dyn Fn(Progress),
) -> Result<PoseSummary, SfmError> {
    let start = Instant::now();
    let files = list_photos(photos)?;
    check_target(out)?;
    if let Some(csv) = &options.control_points {
        // A malformed file fails now, not after COLMAP's minutes.
        read_control_points(csv)?;
    }
    let mut colmap = Colmap::for_engine(options.engine())?.cancelled_by(options.cancel.clone());
    let exif: Vec<PhotoExif> = files.iter().map(|f| read_photo_exif(f)).collect();
    let matching = options
        .matching
        .unwrap_or_else(|| Matching::default_for(files.len()));
    let mut warnings = Vec::new();
    let without_focal = exif.iter().filter(|e| e.focal_35mm.is_none()).count();
    if without_focal > 0 {
        warnings.push(format!(
            "{without_focal} of {} photos have no EXIF focal length: COLMAP starts from 1.2 × \
             the image width and refines it",
            files.len()
        ));
    }

    // Every name in a posed dataset is the pose run's: nothing of an earlier one is carried.
    let run = RunFolder::begin(out, &["*"])?;
    let work = run.path("colmap");
    let images = run.path("images");
    for dir in [&work, &images] {
        std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;
    }
    colmap.prepare(&work)?;
    let log = run.path(LOG_FILE);
    let keep_log = |error: SfmError| keep_failed_log(&log, out, error);
    for file in &files {
        link_or_copy(file, &images.join(file_name(file)))?;
    }
    let masks = copy_masks(photos, &run.path("masks"))?;
    let ignore_masks = masks.as_ref().is_some_and(|m| {
        files
            .iter()
            .all(|f| m.join(format!("{}.png", file_name(f))).is_file())
    });
    if masks.is_some() && !ignore_masks {
        warnings.push(
            "not every photo has an ignore mask (masks/<photo>.png): COLMAP extracts features \
             from whole photos"
                .into(),
        );
    }

    let db = work.join("database.db");
    let threads = options.threads.max(1).to_string();
    let arg = |s: &str| OsString::from(s);
    let path_arg = |p: &Path| p.as_os_str().to_owned();
    let extract = extract_args(
        &db,
        &images,
        options,
        focal_prior(colmap.engine(), &files, &exif),
        masks.as_deref().filter(|_| ignore_masks),
    );
    let n = files.len();
    let step = |command: &str, args: &[OsString]| {
        colmap
            .run(command, args, &log, n, progress)
            .map_err(keep_log)
    };
    step("feature_extractor", &extract)?;
    let mut match_args = vec![
        arg("--database_path"),
        path_arg(&db),
        arg("--SiftMatching.use_gpu"),
        arg("0"),
        arg("--SiftMatching.num_threads"),
        arg(&threads),
    ];
    let matcher = match matching {
        Matching::Exhaustive => "exhaustive_matcher",
        Matching::Sequential => {
            match_args.extend([
                arg("--SequentialMatching.overlap"),
                arg(&options.sequential_overlap.to_string()),
                arg("--SequentialMatching.quadratic_overlap"),
                arg("1"),
            ]);
            "sequential_matcher"
        }
        Matching::Spatial => {
            match_args.extend([arg("--SpatialMatching.is_gps"), arg("1")]);
            "spatial_matcher"
        }
    };
    step(matcher, &match_args)?;
    let sparse = work.join("sparse");
    let map_args = |init: &[&str], seed: Option<u64>, output: &Path| {
        let mut args = vec![
            arg("--database_path"),
            path_arg(&db),
            arg("--image_path"),
            path_arg(&images),
            arg("--output_path"),
            path_arg(output),
            arg("--Mapper.num_threads"),
            arg(&threads),
        ];
        args.extend(MAPPER_SETTINGS.iter().chain(init).map(|s| arg(s)));
        if let Some(seed) = seed {
            args.extend([arg("--Mapper.random_seed"), arg(&seed.to_string())]);
        }
        args
    };
    let no_overlap = || {
        keep_log(SfmError::input(
            photos,
            format!(
                "COLMAP registered no pair of photos (no good initial pair): the {n} photos do \
                 not overlap enough to be posed together (log: {})",
                failed_log_path(out).display()
            ),
        ))
    };
    // The mapper is run once per seed (`mapper_seeds`), each draw into its own folder, and the
    // draw whose centres agree with the photos' GPS and register the most photos is kept
    // (`draws::choose_draw`; docs/POSE.md).
    let run_draw = |seed: Option<u64>| -> Result<(MapperDraw, Vec<ColmapModel>), SfmError> {
        let output = match seed {
            Some(seed) => sparse.join(format!("seed-{seed}")),
            None => sparse.clone(),
        };
        std::fs::create_dir_all(&output).map_err(|e| SceneError::io(&output, e))?;
        // COLMAP 3.8's initial pair is a random search: on lund the same settings found it in
        // one run and not in the next. Mapping is cheap next to matching, so a failed start is
        // retried with looser initial-pair thresholds before the draw counts as empty.
        let mut mapped = false;
        for init in INITIAL_PAIR_SETTINGS {
            // Not `step`: a start the retry or the next seed answers is no failure of the run,
            // and must not leave a `NAME.pose-failed.log` beside a dataset that was made.
            match colmap.run("mapper", &map_args(init, seed, &output), &log, n, progress) {
                Err(SfmError::EngineFailed { tail, .. }) if tail.contains("initial image pair") => {
                }
                other => {
                    other.map_err(keep_log)?;
                    mapped = true;
                    break;
                }
            }
        }
        let mut components = if mapped {
            read_components(&output)?
        } else {
            Vec::new()
        };
        components.sort_by_key(|m| std::cmp::Reverse(m.images.len()));
        let draw = match components.first() {
            Some(model) => MapperDraw::new(
                seed,
                model.images.len(),
                georeference_from_gps(model, &files, &exif).0.as_ref(),
                mean_error(model),
            ),
            None => MapperDraw::new(seed, 0, None, 0.0),
        };
        Ok((draw, components))
    };
    let (first_seeds, more_seeds) = mapper_seeds(colmap.engine());
    let mut draws = Vec::new();
    let mut draw_components = Vec::new();
    let kept_is_implausible = |draws: &[MapperDraw]| {
        choose_draw(draws).and_then(|i| draws[i].gps_plausible()) == Some(false)
    };
    for &seed in first_seeds.iter().chain(more_seeds) {
        // The further seeds only while the kept draw's GPS residual is implausible.
        if draws.len() >= first_seeds.len() && !kept_is_implausible(&draws) {
            break;
        }
        let (draw, components) = run_draw(seed)?;
        draws.push(draw);
        draw_components.push(components);
    }
    let Some(chosen) = choose_draw(&draws) else {
        return Err(no_overlap());
    };
    let gps_plausible = draws[chosen].gps_plausible();
    let model_doubt = (gps_plausible == Some(false)).then(|| {
        let draw = &draws[chosen];
        let (rms, baseline) = (
            draw.gps_rms_m.unwrap_or(f64::NAN),
            draw.gps_baseline_m.unwrap_or(f64::NAN),
        );
        format!(
            "no mapper draw agrees with the photos' GPS: the kept one (seed {}, {} photos) is \
             {rms:.1} m RMS off its GPS fixes over a {baseline:.1} m baseline ({:.0} %, plausible \
             up to {:.0} %) after {} draws: the poses may be wrong; check them, or pose again",
            draw.seed.map_or("none".into(), |s| s.to_string()),
            draw.registered,
            100.0 * rms / baseline,
            100.0 * GPS_PLAUSIBLE_FRACTION,
            draws.len()
        )
    });
    warnings.extend(model_doubt.clone());
    let components = std::mem::take(&mut draw_components[chosen]);

    progress(Progress {
        stage: Stage::Write,
        done: 0,
        total: 1,
    });
    let model = &components[0];
    let registered: Vec<String> = model.images.iter().map(|i| i.name.clone()).collect();
    let unregistered: Vec<String> = files
        .iter()
        .map(|f| file_name(f))
        .filter(|name| !registered.contains(name))
        .collect();
    for name in &unregistered {
        let path = images.join(name);
        std::fs::remove_file(&path).map_err(|e| SceneError::io(&path, e))?;
    }
    let model_dir = run.path("sparse/0");
    std::fs::create_dir_all(&model_dir).map_err(|e| SceneError::io(&model_dir, e))?;
    colmap::write_binary(&model_dir, model)?;

    let (mut georeference, mut georeference_note) = georeference_from_gps(model, &files, &exif);
    let control_points = match &options.control_points {
        Some(csv) => {
            let fit = fit_control_points(model, &model_dir, csv)?;
            georeference = Some(fit.georeference.clone());
            georeference_note = None;
            let json = serde_json::to_string_pretty(&fit)
                .map_err(|e| SceneError::invalid(run.path(CONTROL_FIT_FILE), e.to_string()))?;
            write_atomic(&run.path(CONTROL_FIT_FILE), |w| {
                w.write_all(json.as_bytes())
            })?;
            Some(fit)
        }
        None => None,
    };
    if let Some(g) = georeference
        .as_mut()
        .filter(|g| g.source == GeorefSource::Gps)
    {
        // The twin and its report read the doubt from `georef.json`.
        g.model_doubt = model_doubt;
    }
    if let Some(g) = &georeference {
        g.write(run.staging())?;
    }
    let draws_chosen_seed = draws[chosen].seed;
    let summary = PoseSummary {
        engine: colmap.version(),
        matching,
        photos: n,
        registered,
        unregistered,
        components: components.iter().map(|m| m.images.len()).collect(),
        points: model.points.len(),
        mean_reprojection_error_px: mean_error(model),
        georeference,
        control_points,
        georeference_note,
        mapper_draws: draws,
        chosen_seed: draws_chosen_seed,
        gps_plausible,
        seconds: start.elapsed().as_secs_f64(),
        warnings,
    };
    write_summary_and_commit(run, SUMMARY_FILE, &summary)?;
    Ok(summary)
}

/// Mapper settings beyond COLMAP's defaults, chosen by measurement on the lund photos
/// (docs/POSE.md).
pub(super) const MAPPER_SETTINGS: &[&str] = &["--Mapper.ba_refine_principal_point", "0"];

/// The mapper's seeds, one draw each: the ones always run, then the ones run one by one while
/// the kept draw's GPS residual is implausible (`MapperDraw::gps_plausible`). COLMAP 4
/// (pycolmap) takes `--Mapper.random_seed` and a draw costs 2–6 s of CPU on lund against 40–80 s
/// for extraction and matching, so ten more draws at most add about as much again, and only when
/// the first five are all in doubt (on lund, one run of five); COLMAP 3.8's CLI does not take
/// the option (and its mapper repeated exactly on one database): one draw.
fn mapper_seeds(engine: Engine) -> (&'static [Option<u64>], &'static [Option<u64>]) {
    const FIRST: &[Option<u64>] = &[Some(1), Some(2), Some(3), Some(4), Some(5)];
    const MORE: &[Option<u64>] = &[
        Some(6),
        Some(7),
        Some(8),
        Some(9),
        Some(10),
        Some(11),
        Some(12),
        Some(13),
        Some(14),
        Some(15),
    ];
    match engine {
        Engine::Pycolmap => (FIRST, MORE),
        Engine::Colmap => (&[None], &[]),
    }
}

/// Initial-pair thresholds tried in turn. COLMAP 3.8's defaults (100 inliers, 16°) found no
/// initial pair on lund; the first relaxed set registered all 29 photos within 0.3° of the
/// shipped model in one run and found no pair in another, hence the looser second set.
const INITIAL_PAIR_SETTINGS: &[&[&str]] = &[
    &[
        "--Mapper.init_min_num_inliers",
        "50",
        "--Mapper.init_max_error",
        "8",
        "--Mapper.init_min_tri_angle",
        "8",
    ],
    &[
        "--Mapper.init_min_num_inliers",
        "30",
        "--Mapper.init_max_error",
        "8",
        "--Mapper.init_min_tri_angle",
        "4",
    ],
];

/// The georeference from the registered photos' GPS, or why there is none.
fn georeference_from_gps(
    model: &ColmapModel,
    files: &[PathBuf],
    exif: &[PhotoExif],
) -> (Option<Georeference>, Option<String>) {
    let mut centres = Vec::new();
    for image in &model.images {
        let Some(index) = files.iter().position(|f| file_name(f) == image.name) else {
            continue;
        };
        let (Some(gps), Some((q, t))) = (exif[index].gps, image.pose()) else {
            continue;
        };
        let (q, t) = (q.as_dquat(), t.as_dvec3());
        let centre = -(q.inverse() * t);
        // The camera's up (−y) in the model frame.
        let up = q.inverse() * DVec3::NEG_Y;
        centres.push((image.name.clone(), centre, up, gps));
    }
    if centres.is_empty() {
        return (
            None,
            Some("no registered photo carries EXIF GPS: the dataset has no metres or north".into()),
        );
    }
    match fit_gps(&centres) {
        Ok(g) => (Some(g), None),
        Err(why) => (None, Some(why)),
    }
}
