//! The photo folder and COLMAP workspace shared by `pose` (a new model) and `register` (later
//! photos into a kept model): listing the photos, linking them and their masks into the staged
//! dataset, `feature_extractor`'s arguments, the camera prior from EXIF, the components COLMAP
//! wrote, and the log kept beside the target when a run fails.

use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::scene::SceneError;
use crate::scene::atomic::write_atomic;
use crate::scene::colmap::{self, ColmapModel};
use crate::scene::files::{EntryBudget, image_size, walk_files};
use crate::scene::limits::MAX_LISTED_ENTRIES;
use crate::scene::open::{list_images, stem_of};
use crate::scene::run_folder::RunFolder;
use crate::scene::sfm::SfmError;
use crate::scene::sfm::engine::Engine;
use crate::scene::sfm::exif::PhotoExif;
use crate::scene::sfm::pose::PoseOptions;

/// Writes `summary` as pretty JSON to `name` in the staged dataset, then commits the dataset:
/// the last step of `pose` and of `register`, so a dataset never lacks its summary.
pub(super) fn write_summary_and_commit(
    run: RunFolder,
    name: &str,
    summary: &impl Serialize,
) -> Result<(), SfmError> {
    let path = run.path(name);
    let json = serde_json::to_string_pretty(summary)
        .map_err(|e| SceneError::invalid(&path, e.to_string()))?;
    write_atomic(&path, |w| w.write_all(json.as_bytes()))?;
    run.commit()?;
    Ok(())
}

/// `feature_extractor`'s arguments: one SIMPLE_RADIAL camera for the photos it adds (started
/// from `prior`, `f,cx,cy,k`, when given), CPU SIFT, ignore masks from `masks` when given.
pub(super) fn extract_args(
    db: &Path,
    images: &Path,
    options: &PoseOptions,
    prior: Option<String>,
    masks: Option<&Path>,
) -> Vec<OsString> {
    let mut args: Vec<OsString> = vec![
        "--database_path".into(),
        db.into(),
        "--image_path".into(),
        images.into(),
        "--ImageReader.single_camera".into(),
        "1".into(),
        "--ImageReader.camera_model".into(),
        "SIMPLE_RADIAL".into(),
        "--SiftExtraction.use_gpu".into(),
        "0".into(),
        "--SiftExtraction.num_threads".into(),
        options.threads.max(1).to_string().into(),
        "--SiftExtraction.max_num_features".into(),
        options.max_features.to_string().into(),
    ];
    if let Some(params) = prior {
        args.extend(["--ImageReader.camera_params".into(), params.into()]);
    }
    if let Some(m) = masks {
        args.extend(["--ImageReader.mask_path".into(), m.into()]);
    }
    args
}

/// A failure keeps COLMAP's log beside the target `out` (the staging folder is removed), named
/// so that it is not mistaken for a dataset; an engine failure then names that copy.
pub(super) fn keep_failed_log(log: &Path, out: &Path, error: SfmError) -> SfmError {
    // A cancel leaves nothing, not even a log beside the target.
    if matches!(error, SfmError::Cancelled) {
        return error;
    }
    let kept = failed_log_path(out);
    let copied = std::fs::copy(log, &kept).is_ok();
    match error {
        SfmError::EngineFailed {
            command,
            status,
            tail,
            ..
        } if copied => SfmError::EngineFailed {
            command,
            status,
            tail,
            log: kept,
        },
        other => other,
    }
}

/// The shared camera's starting SIMPLE_RADIAL parameters `f,cx,cy,0` from the photos' EXIF
/// 35 mm-equivalent focal length (`f = f35 / 36 mm × the longer side`), when every photo has
/// one size and the photos that state a focal length agree. COLMAP 3.8 does not read that tag
/// by itself: on lund (no make or model in EXIF) it starts from 1024 px instead of 996 and
/// splits the street in two components (docs/POSE.md). COLMAP 4 reads the photos' EXIF focal
/// length itself, and there the prior hurt: on lund with 995.6 px given it registered 2 of 29
/// photos (docs/POSE.md), so the pycolmap engine gets none.
pub(super) fn focal_prior(engine: Engine, files: &[PathBuf], exif: &[PhotoExif]) -> Option<String> {
    if engine == Engine::Pycolmap {
        return None;
    }
    let mut focals: Vec<f64> = exif.iter().filter_map(|e| e.focal_35mm).collect();
    focals.sort_by(f64::total_cmp);
    let median = *focals.get(focals.len() / 2)?;
    if focals.iter().any(|f| (f - median).abs() > 0.5) {
        return None;
    }
    let size = image_size(files.first()?).ok()?;
    if files[1..].iter().any(|f| image_size(f).ok() != Some(size)) {
        return None;
    }
    let (w, h) = (f64::from(size.0), f64::from(size.1));
    let f = median / 36.0 * w.max(h);
    Some(format!("{f:.2},{},{},0", w / 2.0, h / 2.0))
}

/// Where a failed run's COLMAP log is kept: beside the target, `<name>.pose-failed.log`.
pub fn failed_log_path(out: &Path) -> PathBuf {
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "dataset".into());
    out.with_file_name(format!("{name}.pose-failed.log"))
}

pub(super) fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The photos (JPEG, PNG) directly in `dir`, sorted; at least 2, with distinct stems (masks
/// and views are named by stem).
pub(super) fn list_photos(dir: &Path) -> Result<Vec<PathBuf>, SfmError> {
    if !dir.is_dir() {
        return Err(SfmError::input(dir, "not a folder of photos"));
    }
    let files = list_images(dir, &mut EntryBudget::new(MAX_LISTED_ENTRIES));
    if files.len() < 2 {
        return Err(SfmError::input(
            dir,
            format!(
                "{} photo(s) (JPEG or PNG): structure from motion needs at least 2 overlapping \
                 photos",
                files.len()
            ),
        ));
    }
    let mut stems: Vec<String> = files.iter().map(|f| stem_of(f)).collect();
    stems.sort();
    if let Some(pair) = stems.windows(2).find(|w| w[0] == w[1]) {
        return Err(SfmError::input(
            dir,
            format!(
                "two photos are named {}.*: views and masks are named by the file stem",
                pair[0]
            ),
        ));
    }
    Ok(files)
}

/// The target must not hold anything yet: `pose` never mixes a new model with old files.
pub(super) fn check_target(out: &Path) -> Result<(), SfmError> {
    match std::fs::read_dir(out) {
        Ok(mut entries) => {
            if entries.next().is_some() {
                return Err(SfmError::input(
                    out,
                    "exists and is not empty: choose a new folder for the dataset",
                ));
            }
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(SceneError::io(out, e).into()),
    }
}

pub(super) fn link_or_copy(from: &Path, to: &Path) -> Result<(), SceneError> {
    if let Some(parent) = to.parent() {
        std::fs::create_dir_all(parent).map_err(|e| SceneError::io(parent, e))?;
    }
    if std::fs::hard_link(from, to).is_ok() {
        return Ok(());
    }
    std::fs::copy(from, to)
        .map(|_| ())
        .map_err(|e| SceneError::io(from, e))
}

/// The masks beside the photos (`PHOTOS/masks/`, or `masks/` next to a folder named `images`),
/// copied (every PNG, keeping sub-folders) to `to`; `None` when there are none.
pub(super) fn copy_masks(photos: &Path, to: &Path) -> Result<Option<PathBuf>, SfmError> {
    let beside = photos
        .file_name()
        .is_some_and(|n| n == "images")
        .then(|| photos.with_file_name("masks"));
    let Some(source) = std::iter::once(photos.join("masks"))
        .chain(beside)
        .find(|d| d.is_dir())
    else {
        return Ok(None);
    };
    let is_png = |p: &Path| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"));
    let files = walk_files(
        &source,
        8,
        &mut EntryBudget::new(MAX_LISTED_ENTRIES),
        is_png,
    );
    for relative in &files {
        link_or_copy(&source.join(relative), &to.join(relative))?;
    }
    Ok((!files.is_empty()).then(|| to.to_path_buf()))
}

/// Every model COLMAP's mapper wrote (`sparse/0`, `sparse/1`, …).
pub(super) fn read_components(sparse: &Path) -> Result<Vec<ColmapModel>, SfmError> {
    let mut models = Vec::new();
    let entries = std::fs::read_dir(sparse).map_err(|e| SceneError::io(sparse, e))?;
    for entry in entries.flatten() {
        let dir = entry.path();
        if dir.join("cameras.bin").is_file() {
            models.push(colmap::read_binary(&dir)?);
        }
    }
    Ok(models)
}

pub(super) fn mean_error(model: &ColmapModel) -> f64 {
    let n = model.points.len().max(1) as f64;
    model.points.iter().map(|p| p.error).sum::<f64>() / n
}
