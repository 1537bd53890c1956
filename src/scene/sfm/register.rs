//! A later survey's photos registered by COLMAP into a model that `pose` made and kept, with the
//! old poses held fixed, so the new photos land in that model's frame (the method's "incorporated
//! into the COLMAP pipeline alongside the existing images").
//!
//! The reference dataset's `colmap/database.db` is copied into the new dataset (never changed in
//! place), the new photos' features are extracted into the copy (a camera of their own: another
//! day, maybe another drone), each new photo is matched with every old registered photo and
//! every other new one (`matches_importer` on an explicit pair list: the old pairs are not matched
//! again), and `mapper --input_path <the reference model> --Mapper.fix_existing_images 1`
//! registers and triangulates the new photos around the fixed old poses (with COLMAP's
//! registration thresholds, then looser ones when a new photo was left out). COLMAP 3.8 has both
//! (`image_registrator` registers without triangulating or adjusting, so the new photos would
//! keep their first PnP poses); the mapper continuing a model also skips the initial-pair search
//! that made `pose` unreliable on 3.8 (docs/POSE.md).
//!
//! The dataset holds the whole model (old and new photos; old photos linked from the reference)
//! so that a third survey can be registered into it in turn; `register.json` names the new
//! photos, the reference and the residual: how far the old poses moved (zero when they were held,
//! up to COLMAP's rounding; their shared camera's focal length may still be refined) and the
//! reprojection error of the points the new photos see.

use std::collections::HashSet;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

use crate::scene::SceneError;
use crate::scene::colmap::{self, ColmapImage, ColmapModel};
use crate::scene::files::read_regular;
use crate::scene::open::stem_of;
use crate::scene::run_folder::RunFolder;
use crate::scene::sfm::SfmError;
use crate::scene::sfm::engine::{Colmap, Engine};
use crate::scene::sfm::exif::{PhotoExif, read_photo_exif};
use crate::scene::sfm::georef::Georeference;
use crate::scene::sfm::pose::{LOG_FILE, MAPPER_SETTINGS, PoseOptions, SUMMARY_FILE};
use crate::scene::sfm::progress::{Progress, Stage};
use crate::scene::sfm::workspace::{
    check_target, copy_masks, extract_args, failed_log_path, file_name, focal_prior,
    keep_failed_log, link_or_copy, list_photos, read_components, write_summary_and_commit,
};
use crate::scene::similarity::Similarity;

/// The registration's summary file in the new dataset.
pub const REGISTER_FILE: &str = "register.json";
/// COLMAP's database inside a dataset `pose` (or `register`) wrote.
pub const DATABASE_FILE: &str = "colmap/database.db";
/// The dataset's model.
const MODEL_DIR: &str = "sparse/0";

/// What a registration did, written as `register.json` in the new dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegisterSummary {
    pub engine: String,
    /// The dataset registered into (absolute): the new dataset's model is in its frame.
    pub reference: PathBuf,
    /// New photos given, the ones registered (image names) and the ones COLMAP could not place.
    pub photos: usize,
    pub registered: Vec<String>,
    pub unregistered: Vec<String>,
    pub residual: RegistrationResidual,
    pub seconds: f64,
    pub warnings: Vec<String>,
}

/// How well the new photos sit in the old model, and how much the old model moved.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegistrationResidual {
    /// Old registered photos compared (those in both the reference and the result).
    pub old_images: usize,
    /// Change of the old photos' rotations (degrees) and camera centres (model units).
    pub old_rotation_change_median_deg: f64,
    pub old_rotation_change_max_deg: f64,
    pub old_position_change_median: f64,
    pub old_position_change_max: f64,
    /// RMS distance of the old camera centres to their mean (model units): the scale the
    /// position change is read against.
    pub old_camera_spread: f64,
    /// Largest relative change of an old camera's focal length (the mapper holds poses, not
    /// the intrinsics of a camera the new photos do not share).
    pub old_focal_change_relative: f64,
    /// Mean reprojection error (pixels) of the 3D points the new photos observe, and their count.
    pub new_reprojection_error_px: f64,
    pub new_points: usize,
}

impl RegisterSummary {
    /// A dataset's `register.json`, `None` when the dataset was not made by a registration.
    pub fn read(dataset: &Path) -> Result<Option<RegisterSummary>, SceneError> {
        let path = dataset.join(REGISTER_FILE);
        if !path.exists() {
            return Ok(None);
        }
        let bytes = read_regular(&path, 16 << 20)?;
        serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|e| SceneError::invalid(&path, e.to_string()))
    }
}

/// Registers the photos in `photos` into the model of `reference` (a dataset `pose` or an earlier
/// registration wrote, with its COLMAP workspace) and writes the dataset `out` (new, or an empty
/// folder): the reference's photos and the registered new ones, one model in the reference's
/// frame, the reference's georeference, `register.json`. Nothing is written when no new photo
/// registers or COLMAP fails (its log is kept as `<out>.pose-failed.log`).
pub fn register_photos(
    reference: &Path,
    photos: &Path,
    out: &Path,
    options: &PoseOptions,
    progress: &dyn Fn(Progress),
) -> Result<RegisterSummary, SfmError> {
    let start = Instant::now();
    let reference = std::path::absolute(reference).map_err(|e| SceneError::io(reference, e))?;
    let reference_db = reference.join(DATABASE_FILE);
    let reference_model = reference.join(MODEL_DIR);
    if !reference_db.is_file() || !reference_model.join("images.bin").is_file() {
        return Err(SfmError::input(
            &reference,
            format!(
                "has no COLMAP workspace ({DATABASE_FILE} and {MODEL_DIR}/*.bin): only a dataset \
                 written by `damage-twin pose` or by an earlier `--align colmap` can take a later \
                 survey's photos"
            ),
        ));
    }
    let old = colmap::read_binary(&reference_model)?;
    let files = list_photos(photos)?;
    check_target(out)?;
    let old_stems: HashSet<String> = old
        .images
        .iter()
        .map(|i| stem_of(Path::new(&i.name)))
        .collect();
    if let Some(clash) = files.iter().find(|f| old_stems.contains(&stem_of(f))) {
        return Err(SfmError::input(
            clash,
            format!(
                "the survey registered into ({}) already has a photo named {}.*: views and masks \
                 are named by the file stem, so rename the new photos (for example with the \
                 survey's name in front)",
                reference.display(),
                stem_of(clash)
            ),
        ));
    }
    let engine = match options.engine {
        Some(chosen) => chosen,
        None if Engine::colmap_named() => Engine::Colmap,
        None => engine_of(&reference).unwrap_or_else(Engine::default_choice),
    };
    let mut colmap = Colmap::for_engine(engine)?.cancelled_by(options.cancel.clone());
    let exif: Vec<PhotoExif> = files.iter().map(|f| read_photo_exif(f)).collect();
    let mut warnings = Vec::new();

    let run = RunFolder::begin(out, &["*"])?;
    let work = run.path("colmap");
    let images = run.path("images");
    for dir in [&work, &images] {
        std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;
    }
    colmap.prepare(&work)?;
    let log = run.path(LOG_FILE);
    let keep_log = |error: SfmError| keep_failed_log(&log, out, error);
    let db = run.path(DATABASE_FILE);
    // A copy: the reference survey's workspace stays as it was, whatever happens here.
    std::fs::copy(&reference_db, &db).map_err(|e| SceneError::io(&reference_db, e))?;
    for image in &old.images {
        link_or_copy(
            &reference.join("images").join(&image.name),
            &images.join(&image.name),
        )?;
    }
    let new_names: Vec<String> = files.iter().map(|f| file_name(f)).collect();
    for (file, name) in files.iter().zip(&new_names) {
        link_or_copy(file, &images.join(name))?;
    }
    copy_masks(&reference.join("images"), &run.path("masks"))?;
    let new_masks = copy_masks(photos, &run.path("masks"))?;
    let ignore_masks = new_masks.as_ref().filter(|m| {
        new_names
            .iter()
            .all(|n| m.join(format!("{n}.png")).is_file())
    });

    let list = |file: &str, names: &mut dyn Iterator<Item = String>| -> Result<PathBuf, SfmError> {
        let path = work.join(file);
        let text: String = names.map(|n| n + "\n").collect();
        std::fs::write(&path, text).map_err(|e| SceneError::io(&path, e))?;
        Ok(path)
    };
    let new_list = list("new_images.txt", &mut new_names.iter().cloned())?;
    let old_names: Vec<String> = old.images.iter().map(|i| i.name.clone()).collect();
    let all_list = list(
        "model_images.txt",
        &mut old_names.iter().chain(&new_names).cloned(),
    )?;
    // Every new photo with every old registered one and every other new one.
    let mut pairs = Vec::new();
    for (i, new) in new_names.iter().enumerate() {
        for other in old_names.iter().chain(&new_names[i + 1..]) {
            pairs.push(format!("{new} {other}"));
        }
    }
    let pairs = list("pairs.txt", &mut pairs.into_iter())?;

    let n = old_names.len() + new_names.len();
    let step = |command: &str, args: &[OsString]| {
        colmap
            .run(command, args, &log, n, progress)
            .map_err(keep_log)
    };
    let mut extract = extract_args(
        &db,
        &images,
        options,
        focal_prior(colmap.engine(), &files, &exif),
        ignore_masks.map(PathBuf::as_path),
    );
    extract.extend(["--image_list_path".into(), new_list.into()]);
    step("feature_extractor", &extract)?;
    let threads = options.threads.max(1).to_string();
    let match_args: Vec<OsString> = vec![
        "--database_path".into(),
        db.clone().into(),
        "--match_list_path".into(),
        pairs.into(),
        "--match_type".into(),
        "pairs".into(),
        "--SiftMatching.use_gpu".into(),
        "0".into(),
        "--SiftMatching.num_threads".into(),
        threads.clone().into(),
    ];
    step("matches_importer", &match_args)?;
    let map_args = |output: &Path, settings: &[&str]| {
        let mut args: Vec<OsString> = vec![
            "--database_path".into(),
            db.as_os_str().into(),
            "--image_path".into(),
            images.as_os_str().into(),
            "--input_path".into(),
            reference_model.as_os_str().into(),
            "--output_path".into(),
            output.into(),
            "--image_list_path".into(),
            all_list.as_os_str().into(),
            "--Mapper.fix_existing_images".into(),
            "1".into(),
            // One model: a second one started from new photos alone would be in a frame of its own.
            "--Mapper.multiple_models".into(),
            "0".into(),
            "--Mapper.num_threads".into(),
            threads.as_str().into(),
        ];
        args.extend(MAPPER_SETTINGS.iter().chain(settings).map(OsString::from));
        args
    };
    let is_new = |image: &ColmapImage| new_names.contains(&image.name);
    let count_new = |model: &ColmapModel| model.images.iter().filter(|i| is_new(i)).count();
    // Mapping is cheap next to matching: the default thresholds first, the looser ones when a
    // new photo was left out; the model registering more new photos is kept.
    let mut model = ColmapModel::default();
    for (attempt, settings) in REGISTRATION_SETTINGS.iter().enumerate() {
        let output = work.join(format!("sparse/{attempt}"));
        std::fs::create_dir_all(&output).map_err(|e| SceneError::io(&output, e))?;
        step("mapper", &map_args(&output, settings))?;
        if let Some(continued) = continued_model(&output)?
            && count_new(&continued) > count_new(&model)
        {
            model = continued;
        }
        if count_new(&model) == new_names.len() {
            break;
        }
    }

    progress(Progress {
        stage: Stage::Write,
        done: 0,
        total: 1,
    });
    let registered: Vec<String> = model
        .images
        .iter()
        .filter(|i| is_new(i))
        .map(|i| i.name.clone())
        .collect();
    if registered.is_empty() {
        return Err(keep_log(SfmError::input(
            photos,
            format!(
                "COLMAP registered none of the {} new photos into the model of {}: they do not \
                 overlap its photos enough (log: {})",
                new_names.len(),
                reference.display(),
                failed_log_path(out).display()
            ),
        )));
    }
    let unregistered: Vec<String> = new_names
        .iter()
        .filter(|n| !registered.contains(n))
        .cloned()
        .collect();
    for name in &unregistered {
        let path = images.join(name);
        std::fs::remove_file(&path).map_err(|e| SceneError::io(&path, e))?;
    }
    if !unregistered.is_empty() {
        warnings.push(format!(
            "{} of {} new photos were not registered: {}",
            unregistered.len(),
            new_names.len(),
            unregistered.join(", ")
        ));
    }
    let model = back_to_reference(&old, model);
    let residual = residual(&old, &model, &is_new);
    colmap::write_binary(&run.path(MODEL_DIR), &model)?;
    // Same frame as the reference: its georeference holds as it is.
    if let Some(georef) = Georeference::read(&reference)? {
        georef.write(run.staging())?;
    }
    let summary = RegisterSummary {
        engine: colmap.version(),
        reference,
        photos: new_names.len(),
        registered,
        unregistered,
        residual,
        seconds: start.elapsed().as_secs_f64(),
        warnings,
    };
    write_summary_and_commit(run, REGISTER_FILE, &summary)?;
    Ok(summary)
}

/// The engine that made `dataset` (its `pose.json` or `register.json` names COLMAP's version):
/// by default a later survey is registered by the same one, so a database is never read by
/// another COLMAP than the one that wrote it. `None`: neither file says.
fn engine_of(dataset: &Path) -> Option<Engine> {
    [SUMMARY_FILE, REGISTER_FILE].iter().find_map(|file| {
        let bytes = read_regular(&dataset.join(file), 16 << 20).ok()?;
        let summary: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
        let engine = summary.get("engine")?.as_str()?;
        Some(if engine.contains("pycolmap") {
            Engine::Pycolmap
        } else {
            Engine::Colmap
        })
    })
}

/// Registration thresholds tried in turn: COLMAP's defaults (30 inliers, a quarter of the
/// matches), then looser ones. On lund split in two (photos 01–18 posed, 19–29 registered) the
/// defaults registered none of the new photos (the first, #20, sees 68 old points but gives
/// fewer than 30 inliers: the halves overlap only at their seam); 15 inliers and a tenth
/// registered all 11 within 0.19° and 0.17 % of the shipped model (docs/POSE.md).
const REGISTRATION_SETTINGS: &[&[&str]] = &[
    &[],
    &[
        "--Mapper.abs_pose_min_num_inliers",
        "15",
        "--Mapper.abs_pose_min_inlier_ratio",
        "0.1",
    ],
];

/// The model the mapper wrote when continuing one: COLMAP 3.8 writes it straight into the output
/// folder, a fresh reconstruction goes to `0/`, `1/`, … (the largest is taken). `None`: it
/// wrote none.
fn continued_model(sparse: &Path) -> Result<Option<ColmapModel>, SfmError> {
    if sparse.join("images.bin").is_file() {
        return Ok(Some(colmap::read_binary(sparse)?));
    }
    Ok(read_components(sparse)?
        .into_iter()
        .max_by_key(|m| m.images.len()))
}

/// `model` moved back into `old`'s frame. COLMAP 3.8's mapper normalises the reconstruction
/// after each global bundle adjustment (a shift and a scale; rotations are untouched) even with
/// `fix_existing_images`: on lund the held old cameras came back 0.000° turned but shifted by
/// 158 % of their spread. The old cameras are held relative to each other, so the similarity
/// taking their centres back onto the reference's undoes it exactly; it is applied to every
/// camera and point.
fn back_to_reference(old: &ColmapModel, mut model: ColmapModel) -> ColmapModel {
    let (mut from, mut to) = (Vec::new(), Vec::new());
    for before in &old.images {
        let after = model.images.iter().find(|i| i.id == before.id);
        if let (Some((_, c0)), Some((_, c1))) = (
            rotation_and_centre(before),
            after.and_then(rotation_and_centre),
        ) {
            from.push(c1);
            to.push(c0);
        }
    }
    // Scale and shift only (least squares), as COLMAP's normalisation applies: no rotation to
    // fit, so cameras along one line (a street) fit as well as any.
    let n = from.len().max(1) as f64;
    let (mean_from, mean_to) = (from.iter().sum::<DVec3>() / n, to.iter().sum::<DVec3>() / n);
    let spread: f64 = from.iter().map(|f| f.distance_squared(mean_from)).sum();
    if !(spread > 1e-18) {
        return model;
    }
    let scale = from
        .iter()
        .zip(&to)
        .map(|(f, t)| (*f - mean_from).dot(*t - mean_to))
        .sum::<f64>()
        / spread;
    let fit = Similarity {
        scale,
        rotation: DQuat::IDENTITY.to_array(),
        translation: (mean_to - scale * mean_from).to_array(),
    };
    let (rotation, translation) = (fit.quat(), DVec3::from_array(fit.translation));
    for image in &mut model.images {
        let Some((q, _)) = rotation_and_centre(image) else {
            continue;
        };
        // x_cam = q·x + t with x = R⁻¹(x′ − T)/s, the camera frame scaled by s:
        // q′ = q·R⁻¹, t′ = s·t − q′·T.
        let turned = q * rotation.inverse();
        let shifted = fit.scale * DVec3::from_array(image.tvec) - turned * translation;
        image.qvec = [turned.w, turned.x, turned.y, turned.z];
        image.tvec = shifted.to_array();
    }
    for point in &mut model.points {
        point.xyz = fit.apply(DVec3::from_array(point.xyz)).to_array();
    }
    model
}

/// World-to-camera rotation and camera centre of an image, in double precision.
fn rotation_and_centre(image: &ColmapImage) -> Option<(DQuat, DVec3)> {
    let [w, x, y, z] = image.qvec;
    let q = DQuat::from_xyzw(x, y, z, w);
    let norm = q.length();
    if !(norm > 1e-12 && norm.is_finite()) {
        return None;
    }
    let q = q / norm;
    let t = DVec3::from_array(image.tvec);
    t.is_finite().then(|| (q, -(q.inverse() * t)))
}

/// How far the old photos moved between `old` and `new` (matched by image id, which the copied
/// database keeps) and how well the new photos' points fit.
pub fn residual(
    old: &ColmapModel,
    new: &ColmapModel,
    is_new: &dyn Fn(&ColmapImage) -> bool,
) -> RegistrationResidual {
    let mut rotation = Vec::new();
    let mut position = Vec::new();
    let mut centres = Vec::new();
    for before in &old.images {
        let Some(after) = new.images.iter().find(|i| i.id == before.id) else {
            continue;
        };
        let (Some((qa, ca)), Some((qb, cb))) =
            (rotation_and_centre(before), rotation_and_centre(after))
        else {
            continue;
        };
        rotation.push(qa.angle_between(qb).to_degrees());
        position.push(ca.distance(cb));
        centres.push(ca);
    }
    let mean = centres.iter().copied().sum::<DVec3>() / centres.len().max(1) as f64;
    let spread = (centres
        .iter()
        .map(|c| c.distance_squared(mean))
        .sum::<f64>()
        / centres.len().max(1) as f64)
        .sqrt();
    let focal_change = old
        .cameras
        .iter()
        .filter_map(|before| {
            let after = new.cameras.iter().find(|c| c.id == before.id)?;
            let (f0, f1) = (*before.params.first()?, *after.params.first()?);
            (f0 > 0.0).then(|| ((f1 - f0) / f0).abs())
        })
        .fold(0.0, f64::max);
    let new_ids: HashSet<u32> = new
        .images
        .iter()
        .filter(|i| is_new(i))
        .map(|i| i.id)
        .collect();
    let seen: Vec<f64> = new
        .points
        .iter()
        .filter(|p| p.track.iter().any(|(id, _)| new_ids.contains(id)))
        .map(|p| p.error)
        .collect();
    RegistrationResidual {
        old_images: rotation.len(),
        old_rotation_change_median_deg: median(&mut rotation.clone()),
        old_rotation_change_max_deg: rotation.iter().copied().fold(0.0, f64::max),
        old_position_change_median: median(&mut position.clone()),
        old_position_change_max: position.iter().copied().fold(0.0, f64::max),
        old_camera_spread: spread,
        old_focal_change_relative: focal_change,
        new_reprojection_error_px: seen.iter().sum::<f64>() / seen.len().max(1) as f64,
        new_points: seen.len(),
    }
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    values.get(values.len() / 2).copied().unwrap_or(0.0)
}
