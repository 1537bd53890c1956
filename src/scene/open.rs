//! `Dataset::open`: recognises a dataset folder (COLMAP `sparse/` + `images/`, `transforms.json`,
//! NeRF-synthetic `transforms_train.json`) and reads its metadata into a `Dataset`.
//! Reads no pixels: only each view's image header, to check its camera against the image as
//! stored before anything is sized from it. Never decodes damage masks per view.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::scene::colmap::{self, ColmapModel, ColmapPoint};
use crate::scene::files::{EntryBudget, image_size, list_dir, walk_files};
use crate::scene::limits::{
    MAX_LISTED_ENTRIES, MAX_POINT_COORDINATE, MAX_VIEWS, check_image_size, is_usable_position,
};
use crate::scene::{
    Camera, Dataset, DatasetFormat, Distortion, Intrinsics, MaskFolder, MaskSource, PointCloud,
    SceneError, Split, View,
};

/// How a dataset is opened.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OpenOptions {
    /// Colour RGBA images are composited on when loaded (NeRF-synthetic is usually shown on
    /// white; black is the default as in 3DGS).
    pub background: [f32; 3],
}

impl Default for OpenOptions {
    fn default() -> Self {
        OpenOptions {
            background: [0.0; 3],
        }
    }
}

/// Image file extensions damage-twin decodes (the `image` crate's enabled formats).
pub(crate) fn is_image_file(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["png", "jpg", "jpeg"].contains(&e.to_ascii_lowercase().as_str()))
}

/// Image files in `dir` (not recursive), sorted; an unreadable or missing folder lists nothing.
pub(crate) fn list_images(dir: &Path, budget: &mut EntryBudget) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = list_dir(dir, budget)
        .into_iter()
        .filter(|p| p.is_file() && is_image_file(p))
        .collect();
    files.sort();
    files
}

/// Image files under `dir` and its sub-folders (COLMAP names may contain `/`), as `/`-separated
/// paths relative to `dir`, sorted. Eight folders deep at most, no link followed back into the
/// walk, every entry counted against `budget`.
fn list_images_recursive(dir: &Path, budget: &mut EntryBudget) -> Vec<String> {
    walk_files(dir, 8, budget, is_image_file)
}

/// The warning for a listing cut short by its budget, if it was.
pub(crate) fn budget_warning(budget: &EntryBudget) -> Option<String> {
    budget.exhausted_in().map(|dir| {
        format!(
            "stopped listing files after {MAX_LISTED_ENTRIES} folder entries (in {}): image and \
             mask counts are incomplete",
            dir.display()
        )
    })
}

/// Refuses a dataset listing more views than `MAX_VIEWS`, naming the file that lists them.
pub(crate) fn check_view_count(file: &Path, count: usize, what: &str) -> Result<(), SceneError> {
    if count > MAX_VIEWS {
        return Err(SceneError::invalid(
            file,
            format!("{count} {what}: more than the {MAX_VIEWS} views a dataset may have"),
        ));
    }
    Ok(())
}

/// Checks every view's camera against its image as stored, reading each file's header once
/// (several views may share one file): the image must be within the size limits, and the same
/// size as its camera or a copy downscaled by 2, 4 or 8 (what `load_view` accepts). Done at open,
/// so nothing is ever sized from a camera that lies about its image.
pub(crate) fn check_views_against_images(views: &[View]) -> Result<(), SceneError> {
    let mut sizes: HashMap<&Path, (u32, u32)> = HashMap::new();
    for view in views {
        let path = view.image_path.as_path();
        let stored = match sizes.get(path) {
            Some(&size) => size,
            None => {
                let size = image_size(path)?;
                check_image_size(u64::from(size.0), u64::from(size.1))
                    .map_err(|m| SceneError::invalid(path, m))?;
                sizes.insert(path, size);
                size
            }
        };
        crate::scene::load::stored_geometry(view, stored)?;
    }
    Ok(())
}

/// One warning for a list of names: the count, then at most a few of them.
pub(crate) fn summarise(what: &str, names: &[String]) -> String {
    const SHOWN: usize = 5;
    let mut shown = names
        .iter()
        .take(SHOWN)
        .cloned()
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > SHOWN {
        shown.push_str(&format!(", … ({} more)", names.len() - SHOWN));
    }
    format!("{} {what}: {shown}", names.len())
}

/// The file stem a view and its masks are named by.
pub(crate) fn stem_of(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// `masks/` beside the images as the dataset's mask source, and its per-class counts.
pub(crate) fn find_masks(
    root: &Path,
    budget: &mut EntryBudget,
) -> (
    Option<Arc<dyn MaskSource>>,
    BTreeMap<crate::scene::DamageClass, usize>,
) {
    let dir = root.join("masks");
    if dir.is_dir() {
        let counts = crate::scene::masks::count_masks_within(&dir, budget);
        (Some(MaskFolder::shared(dir)), counts)
    } else {
        (None, BTreeMap::new())
    }
}

/// Camera models with the number of distinct cameras using each.
pub(crate) fn count_models<'a>(names: impl Iterator<Item = &'a str>) -> BTreeMap<String, usize> {
    let mut out = BTreeMap::new();
    for n in names {
        *out.entry(n.to_owned()).or_insert(0) += 1;
    }
    out
}

impl Dataset {
    /// Opens the dataset at `path` (a folder, or a `transforms*.json` file inside one).
    pub fn open(path: &Path, options: &OpenOptions) -> Result<Dataset, SceneError> {
        let meta = std::fs::metadata(path).map_err(|e| SceneError::io(path, e))?;
        let root = if meta.is_file() {
            let is_transforms = path
                .file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("transforms") && n.ends_with(".json"));
            if !is_transforms {
                return Err(SceneError::invalid(
                    path,
                    "not a dataset: give a folder (COLMAP or transforms.json)",
                ));
            }
            path.parent().unwrap_or(Path::new("."))
        } else {
            path
        };
        if let Some((sparse, format)) = find_sparse(root)? {
            return open_colmap(root, &sparse, format, options);
        }
        if root.join("transforms.json").is_file() || root.join("transforms_train.json").is_file() {
            return crate::scene::transforms::open_transforms(root, options);
        }
        Err(SceneError::invalid(
            root,
            "not a recognised dataset: expected sparse/0/ or sparse/ (COLMAP cameras, images, \
             points3D as .bin or .txt) with images/, or transforms.json, or transforms_train.json",
        ))
    }
}

/// The COLMAP model folder (`sparse/0/`, then `sparse/`) and whether it is binary or text.
fn find_sparse(root: &Path) -> Result<Option<(PathBuf, DatasetFormat)>, SceneError> {
    for dir in [root.join("sparse").join("0"), root.join("sparse")] {
        if dir.join("cameras.bin").is_file() {
            return Ok(Some((dir, DatasetFormat::ColmapBinary)));
        }
        if dir.join("cameras.txt").is_file() {
            return Ok(Some((dir, DatasetFormat::ColmapText)));
        }
    }
    if root.join("sparse").is_dir() {
        return Err(SceneError::invalid(
            root.join("sparse"),
            "no COLMAP model: neither sparse/0/ nor sparse/ holds cameras.bin or cameras.txt",
        ));
    }
    Ok(None)
}

fn open_colmap(
    root: &Path,
    sparse: &Path,
    format: DatasetFormat,
    options: &OpenOptions,
) -> Result<Dataset, SceneError> {
    let model: ColmapModel = match format {
        DatasetFormat::ColmapText => colmap::read_text(sparse)?,
        _ => colmap::read_binary(sparse)?,
    };
    let ext = if format == DatasetFormat::ColmapText {
        "txt"
    } else {
        "bin"
    };
    let cameras_file = sparse.join(format!("cameras.{ext}"));
    let images_file = sparse.join(format!("images.{ext}"));
    let points_file = sparse.join(format!("points3D.{ext}"));
    let images_dir = root.join("images");
    if !images_dir.is_dir() {
        return Err(SceneError::invalid(
            &images_dir,
            "the COLMAP model has no images/ folder beside sparse/",
        ));
    }
    check_view_count(&images_file, model.images.len(), "registered images")?;

    let mut budget = EntryBudget::new(MAX_LISTED_ENTRIES);
    let on_disk = list_images_recursive(&images_dir, &mut budget);
    let mut pinholes: BTreeMap<u32, (Intrinsics, Option<Distortion>)> = BTreeMap::new();
    let mut views = Vec::new();
    let mut missing = Vec::new();
    let mut registered_names = BTreeSet::new();
    for im in &model.images {
        registered_names.insert(im.name.as_str());
        let pinhole = match pinholes.get(&im.camera_id) {
            Some(p) => *p,
            None => {
                let Some(cam) = model.cameras.iter().find(|c| c.id == im.camera_id) else {
                    return Err(SceneError::invalid(
                        &images_file,
                        format!(
                            "image {} ({}) uses camera {}, which {} does not define",
                            im.id,
                            im.name,
                            im.camera_id,
                            cameras_file.display()
                        ),
                    ));
                };
                let p = cam.to_pinhole(&cameras_file)?;
                pinholes.insert(im.camera_id, p);
                p
            }
        };
        let Some((rotation, translation)) = im.pose() else {
            return Err(SceneError::invalid(
                &images_file,
                format!("image {} ({}): pose is not finite", im.id, im.name),
            ));
        };
        let image_path = images_dir.join(&im.name);
        if !image_path.is_file() {
            missing.push(im.name.clone());
            continue;
        }
        views.push(View {
            name: stem_of(&image_path),
            image_path,
            camera: Camera::new(pinhole.0, rotation, translation),
            distortion: pinhole.1,
            split: Split::Unspecified,
            ignore_mask: None,
        });
    }
    if views.is_empty() {
        return Err(SceneError::invalid(
            &images_file,
            format!(
                "no usable view: {} registered images, none found under {}",
                model.images.len(),
                images_dir.display()
            ),
        ));
    }
    views.sort_by(|a, b| (&a.name, &a.image_path).cmp(&(&b.name, &b.image_path)));
    check_views_against_images(&views)?;

    let mut warnings = Vec::new();
    if !missing.is_empty() {
        warnings.push(summarise(
            &format!("registered images missing from {}", images_dir.display()),
            &missing,
        ));
    }
    let unregistered: Vec<String> = on_disk
        .iter()
        .filter(|n| !registered_names.contains(n.as_str()))
        .cloned()
        .collect();
    if !unregistered.is_empty() {
        warnings.push(summarise(
            "images without a pose (unregistered)",
            &unregistered,
        ));
    }

    let (points, skipped) = usable_points(&model.points);
    if !skipped.is_empty() {
        let ids: Vec<String> = skipped.iter().map(|id| format!("id {id}")).collect();
        warnings.push(summarise(
            &format!(
                "points of {} skipped (a coordinate not finite or beyond ±{MAX_POINT_COORDINATE:e})",
                points_file.display()
            ),
            &ids,
        ));
    }
    let (masks, mask_counts) = find_masks(root, &mut budget);
    warnings.extend(budget_warning(&budget));
    Ok(Dataset {
        root: root.to_path_buf(),
        format,
        views,
        image_files: on_disk.len(),
        camera_count: model.cameras.len(),
        camera_models: count_models(model.cameras.iter().map(|c| c.model.name())),
        points,
        masks,
        mask_counts,
        background: options.background,
        warnings,
        view_cache: None,
    })
}

/// The SfM points that can seed Gaussians (`limits::is_usable_position`), and the COLMAP ids of
/// those skipped. No usable point gives `None`.
fn usable_points(points: &[ColmapPoint]) -> (Option<PointCloud>, Vec<u64>) {
    let mut cloud = PointCloud::default();
    let mut skipped = Vec::new();
    for p in points {
        if is_usable_position(p.xyz) {
            cloud
                .positions
                .push(glam::DVec3::from_array(p.xyz).as_vec3());
            cloud.colours.push(p.rgb);
        } else {
            skipped.push(p.id);
        }
    }
    ((!cloud.is_empty()).then_some(cloud), skipped)
}
