//! `Dataset::open`: recognises a dataset folder (COLMAP `sparse/` + `images/`, `transforms.json`,
//! NeRF-synthetic `transforms_train.json`) and reads its metadata into a `Dataset`.
//! Reads no pixels (only image headers where a format omits the size); never decodes masks.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::scene::colmap::{self, ColmapModel};
use crate::scene::{
    Camera, Dataset, DatasetFormat, Distortion, Intrinsics, PointCloud, SceneError, Split, View,
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
pub(crate) fn list_images(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && is_image_file(p))
        .collect();
    files.sort();
    files
}

/// Image files under `dir` and its sub-folders (COLMAP names may contain `/`), as `/`-separated
/// paths relative to `dir`, sorted. Depth-limited so a link cycle cannot recurse forever.
fn list_images_recursive(dir: &Path) -> Vec<String> {
    fn walk(dir: &Path, prefix: &str, depth: usize, out: &mut Vec<String>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for entry in entries.filter_map(|e| e.ok()) {
            let path = entry.path();
            let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
                continue;
            };
            if name.starts_with('.') {
                continue;
            }
            let rel = format!("{prefix}{name}");
            if path.is_dir() && depth < 8 {
                walk(&path, &format!("{rel}/"), depth + 1, out);
            } else if path.is_file() && is_image_file(&path) {
                out.push(rel);
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, "", 0, &mut out);
    out.sort();
    out
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

/// `masks/` beside the images and its per-class counts.
pub(crate) fn find_masks(
    root: &Path,
) -> (Option<PathBuf>, BTreeMap<crate::scene::DamageClass, usize>) {
    let dir = root.join("masks");
    if dir.is_dir() {
        let counts = crate::scene::masks::count_masks(&dir);
        (Some(dir), counts)
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
    let images_dir = root.join("images");
    if !images_dir.is_dir() {
        return Err(SceneError::invalid(
            &images_dir,
            "the COLMAP model has no images/ folder beside sparse/",
        ));
    }

    let on_disk = list_images_recursive(&images_dir);
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

    let points = (!model.points.is_empty()).then(|| PointCloud {
        positions: model
            .points
            .iter()
            .map(|p| glam::DVec3::from_array(p.xyz).as_vec3())
            .collect(),
        colours: model.points.iter().map(|p| p.rgb).collect(),
    });
    let (masks_dir, mask_counts) = find_masks(root);
    Ok(Dataset {
        root: root.to_path_buf(),
        format,
        views,
        image_files: on_disk.len(),
        camera_count: model.cameras.len(),
        camera_models: count_models(model.cameras.iter().map(|c| c.model.name())),
        points,
        masks_dir,
        mask_counts,
        background: options.background,
        warnings,
    })
}
