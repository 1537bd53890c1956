//! `transforms.json` datasets: nerfstudio, instant-ngp and NeRF-synthetic (`transforms_train.json`
//! and `transforms_test.json`). OpenGL camera-to-world poses become COLMAP world-to-camera ones here,
//! once. Frames whose image is missing are skipped with one warning per file; no pixels are read.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::ffi::OsString;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::scene::files::{EntryBudget, image_size, read_regular};
use crate::scene::limits::{
    MAX_LISTED_ENTRIES, MAX_POINT_COORDINATE, MAX_TRANSFORMS_BYTES, check_image_size,
};
use crate::scene::open::{
    OpenOptions, budget_warning, check_view_count, check_views_against_images, count_models,
    find_masks, is_image_file, list_images, stem_of, summarise,
};
use crate::scene::{
    Camera, Dataset, DatasetFormat, Distortion, Intrinsics, SceneError, Split, View,
};

/// Lens fields, global or per frame (a frame's value wins).
#[derive(Clone, Debug, Default, Deserialize)]
struct Lens {
    camera_angle_x: Option<f64>,
    camera_angle_y: Option<f64>,
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
    k1: Option<f64>,
    k2: Option<f64>,
    k3: Option<f64>,
    k4: Option<f64>,
    p1: Option<f64>,
    p2: Option<f64>,
    camera_model: Option<String>,
    is_fisheye: Option<bool>,
}

impl Lens {
    fn or(&self, global: &Lens) -> Lens {
        Lens {
            camera_angle_x: self.camera_angle_x.or(global.camera_angle_x),
            camera_angle_y: self.camera_angle_y.or(global.camera_angle_y),
            fl_x: self.fl_x.or(global.fl_x),
            fl_y: self.fl_y.or(global.fl_y),
            cx: self.cx.or(global.cx),
            cy: self.cy.or(global.cy),
            w: self.w.or(global.w),
            h: self.h.or(global.h),
            k1: self.k1.or(global.k1),
            k2: self.k2.or(global.k2),
            k3: self.k3.or(global.k3),
            k4: self.k4.or(global.k4),
            p1: self.p1.or(global.p1),
            p2: self.p2.or(global.p2),
            camera_model: self.camera_model.clone().or(global.camera_model.clone()),
            is_fisheye: self.is_fisheye.or(global.is_fisheye),
        }
    }
}

#[derive(Debug, Deserialize)]
struct Frame {
    file_path: String,
    /// nerfstudio: the frame's ignore mask (0 = ignore), relative to the file's folder.
    #[serde(default)]
    mask_path: Option<String>,
    /// 4×4 (or 3×4) camera-to-world, rows, OpenGL camera axes.
    transform_matrix: Vec<Vec<f64>>,
    #[serde(flatten)]
    lens: Lens,
}

/// Only the number of frames, counted without keeping them: a first pass so that a file listing
/// millions of frames is refused before they are parsed into memory.
#[derive(Deserialize)]
struct FrameCount {
    #[serde(deserialize_with = "count_elements")]
    frames: usize,
}

fn count_elements<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<usize, D::Error> {
    struct Counter;
    impl<'de> serde::de::Visitor<'de> for Counter {
        type Value = usize;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a list of frames")
        }
        fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<usize, A::Error> {
            let mut n = 0usize;
            while seq.next_element::<serde::de::IgnoredAny>()?.is_some() {
                n += 1;
            }
            Ok(n)
        }
    }
    deserializer.deserialize_seq(Counter)
}

#[derive(Debug, Deserialize)]
struct TransformsFile {
    #[serde(flatten)]
    lens: Lens,
    ply_file_path: Option<String>,
    frames: Vec<Frame>,
}

/// A view read from one json, before sorting, with the camera it uses.
struct Parsed {
    views: Vec<View>,
    /// Parent folders of the listed frames (where image files are counted).
    image_dirs: BTreeSet<PathBuf>,
    referenced: BTreeSet<PathBuf>,
    /// (model name, exact intrinsics + distortion bits) per view, to count distinct cameras.
    cameras: Vec<(String, [u32; 10])>,
    ply_file_path: Option<String>,
}

/// Opens a folder with `transforms.json` (nerfstudio, instant-ngp), else NeRF-synthetic
/// `transforms_train.json` (+ `transforms_test.json`; `transforms_val.json` is not used, as in
/// 3DGS's Blender loader which trains on train and evaluates on test).
pub fn open_transforms(root: &Path, options: &OpenOptions) -> Result<Dataset, SceneError> {
    let mut warnings = Vec::new();
    let mut parsed = Vec::new();
    let single = root.join("transforms.json");
    if single.is_file() {
        parsed.push(read_json(root, &single, Split::Unspecified, &mut warnings)?);
    } else {
        parsed.push(read_json(
            root,
            &root.join("transforms_train.json"),
            Split::Train,
            &mut warnings,
        )?);
        let test = root.join("transforms_test.json");
        if test.is_file() {
            parsed.push(read_json(root, &test, Split::Test, &mut warnings)?);
        }
    }

    let mut views = Vec::new();
    let mut image_dirs = BTreeSet::new();
    let mut referenced = BTreeSet::new();
    let mut cameras = BTreeSet::new();
    let mut points = None;
    for p in parsed {
        views.extend(p.views);
        image_dirs.extend(p.image_dirs);
        referenced.extend(p.referenced);
        cameras.extend(p.cameras);
        if let Some(ply) = p.ply_file_path {
            let path = root.join(&ply);
            if path.is_file() {
                let (cloud, skipped) = crate::scene::ply::read_point_cloud_skipping(&path)?;
                if !skipped.is_empty() {
                    let vertices: Vec<String> =
                        skipped.iter().map(|v| format!("vertex {v}")).collect();
                    warnings.push(summarise(
                        &format!(
                            "points of {} skipped (a coordinate not finite or beyond \
                             ±{MAX_POINT_COORDINATE:e})",
                            path.display()
                        ),
                        &vertices,
                    ));
                }
                points = (!cloud.is_empty()).then_some(cloud);
            } else {
                warnings.push(format!(
                    "ply_file_path {} does not exist: no initial points",
                    path.display()
                ));
            }
        }
    }
    if views.is_empty() {
        return Err(SceneError::invalid(
            root,
            "no usable view: no frame of the transforms file(s) has an image file",
        ));
    }
    views.sort_by(|a, b| (&a.name, &a.image_path).cmp(&(&b.name, &b.image_path)));
    check_views_against_images(&views)?;

    let mut budget = EntryBudget::new(MAX_LISTED_ENTRIES);
    let on_disk: Vec<PathBuf> = image_dirs
        .iter()
        .flat_map(|d| list_images(d, &mut budget))
        .collect();
    let unregistered: Vec<String> = on_disk
        .iter()
        .filter(|p| !referenced.contains(*p))
        .map(|p| relative(root, p))
        .collect();
    if !unregistered.is_empty() {
        warnings.push(summarise(
            "image files no frame lists (unregistered)",
            &unregistered,
        ));
    }

    let (masks, mask_counts) = find_masks(root, &mut budget);
    warnings.extend(budget_warning(&budget));
    Ok(Dataset {
        root: root.to_path_buf(),
        format: DatasetFormat::Transforms,
        views,
        image_files: on_disk.len(),
        camera_count: cameras.len(),
        camera_models: count_models(cameras.iter().map(|(m, _)| m.as_str())),
        points,
        masks,
        mask_counts,
        background: options.background,
        warnings,
        view_cache: None,
    })
}

fn relative(root: &Path, path: &Path) -> String {
    path.strip_prefix(root)
        .unwrap_or(path)
        .to_string_lossy()
        .into_owned()
}

/// The image a `file_path` names: as written, else with an image extension appended
/// (NeRF-synthetic writes `./train/r_0` for `train/r_0.png`).
fn resolve(root: &Path, file_path: &str) -> Option<PathBuf> {
    let path = root.join(file_path);
    if path.is_file() {
        return Some(path);
    }
    if is_image_file(&path) {
        return None;
    }
    ["png", "jpg", "jpeg", "PNG", "JPG", "JPEG"]
        .iter()
        .map(|ext| {
            let mut s = OsString::from(path.as_os_str());
            s.push(".");
            s.push(ext);
            PathBuf::from(s)
        })
        .find(|p| p.is_file())
}

fn read_json(
    root: &Path,
    json_path: &Path,
    split: Split,
    warnings: &mut Vec<String>,
) -> Result<Parsed, SceneError> {
    let bytes = read_regular(json_path, MAX_TRANSFORMS_BYTES)?;
    let not_transforms = |e: serde_json::Error| {
        SceneError::invalid(json_path, format!("not a transforms file: {e}"))
    };
    let count: FrameCount = serde_json::from_slice(&bytes).map_err(not_transforms)?;
    check_view_count(json_path, count.frames, "frames")?;
    let file: TransformsFile = serde_json::from_slice(&bytes).map_err(not_transforms)?;
    let mut out = Parsed {
        views: Vec::new(),
        image_dirs: BTreeSet::new(),
        referenced: BTreeSet::new(),
        cameras: Vec::new(),
        ply_file_path: file.ply_file_path.clone(),
    };
    let mut missing = Vec::new();
    let mut sizes = HashMap::new();
    for (index, frame) in file.frames.iter().enumerate() {
        let listed = root.join(&frame.file_path);
        if let Some(dir) = listed.parent() {
            out.image_dirs.insert(dir.to_path_buf());
        }
        let Some(image_path) = resolve(root, &frame.file_path) else {
            missing.push(frame.file_path.clone());
            continue;
        };
        let invalid = |message: String| {
            SceneError::invalid(
                json_path,
                format!("frame {index} ({}): {message}", frame.file_path),
            )
        };
        let c2w = matrix(&frame.transform_matrix).map_err(invalid)?;
        let lens = frame.lens.or(&file.lens);
        let (intrinsics, distortion, model) =
            lens_to_pinhole(&lens, &image_path, json_path, &mut sizes).map_err(|e| match e {
                LensError::Invalid(m) => invalid(m),
                LensError::Scene(e) => e,
            })?;
        out.cameras
            .push((model, camera_key(&intrinsics, distortion.as_ref())));
        out.referenced.insert(image_path.clone());
        // A named mask that is not there is a dataset error: training on the whole photo would
        // learn what the mask was made to keep out.
        let ignore_mask = match &frame.mask_path {
            Some(m) => {
                let path = root.join(m);
                if !path.is_file() {
                    return Err(invalid(format!(
                        "mask_path {} does not exist",
                        path.display()
                    )));
                }
                Some(path)
            }
            None => None,
        };
        out.views.push(View {
            name: stem_of(&image_path),
            camera: Camera::from_opengl_camera_to_world(intrinsics, c2w),
            image_path,
            distortion,
            split,
            ignore_mask,
        });
    }
    if !missing.is_empty() {
        let name = json_path.file_name().unwrap_or_default().to_string_lossy();
        warnings.push(summarise(
            &format!(
                "of {} frames in {name} skipped, image file missing",
                file.frames.len()
            ),
            &missing,
        ));
    }
    Ok(out)
}

/// Exact bits of a camera, so that per-frame copies of one lens count as one camera.
fn camera_key(k: &Intrinsics, d: Option<&Distortion>) -> [u32; 10] {
    let d = d.copied().map_or([0.0; 4], |d| [d.k1, d.k2, d.p1, d.p2]);
    [
        k.width,
        k.height,
        k.fx.to_bits(),
        k.fy.to_bits(),
        k.cx.to_bits(),
        k.cy.to_bits(),
        d[0].to_bits(),
        d[1].to_bits(),
        d[2].to_bits(),
        d[3].to_bits(),
    ]
}

/// A row-major 4×4 (or 3×4) camera-to-world matrix, checked finite and invertible.
fn matrix(rows: &[Vec<f64>]) -> Result<glam::Mat4, String> {
    if !(rows.len() == 3 || rows.len() == 4) || rows.iter().any(|r| r.len() != 4) {
        return Err("transform_matrix must be 4x4 (or 3x4)".into());
    }
    let mut m = [[0.0f32; 4]; 4];
    for (i, row) in rows.iter().enumerate() {
        for (j, &v) in row.iter().enumerate() {
            // Stored as columns for glam.
            m[j][i] = v as f32;
        }
    }
    if rows.len() == 3 {
        m[3][3] = 1.0;
    }
    let m = glam::Mat4::from_cols_array_2d(&m);
    let det = glam::Mat3::from_mat4(m).determinant();
    // `!(|det| > eps)` also rejects NaN.
    if !(det.abs() > 1e-6) || !m.is_finite() {
        return Err("transform_matrix is not a finite, invertible pose".into());
    }
    Ok(m)
}

enum LensError {
    Invalid(String),
    Scene(SceneError),
}

/// Intrinsics of one frame; width and height come from the image header when not given (read
/// once per file: `sizes` keeps those already read).
fn lens_to_pinhole(
    lens: &Lens,
    image_path: &Path,
    json_path: &Path,
    sizes: &mut HashMap<PathBuf, (u32, u32)>,
) -> Result<(Intrinsics, Option<Distortion>, String), LensError> {
    let model = lens.camera_model.as_deref();
    if !matches!(model, None | Some("OPENCV") | Some("PINHOLE")) || lens.is_fisheye == Some(true) {
        return Err(LensError::Scene(SceneError::unsupported(
            json_path,
            format!(
                "camera model {} (only PINHOLE and OPENCV can be undistorted)",
                model.unwrap_or("fisheye")
            ),
        )));
    }
    for (name, v) in [("k3", lens.k3), ("k4", lens.k4)] {
        if v.is_some_and(|v| v != 0.0) {
            return Err(LensError::Scene(SceneError::unsupported(
                json_path,
                format!("distortion coefficient {name} (only k1 k2 p1 p2 are undistorted)"),
            )));
        }
    }
    let (w, h) = match (lens.w, lens.h) {
        (Some(w), Some(h)) => (w, h),
        _ => {
            let (w, h) = match sizes.get(image_path) {
                Some(&size) => size,
                None => {
                    let size = image_size(image_path).map_err(LensError::Scene)?;
                    sizes.insert(image_path.to_path_buf(), size);
                    size
                }
            };
            (w as f64, h as f64)
        }
    };
    // `!(x >= 1)` rejects NaN as well; the limit keeps the rounding below exact.
    if !(w >= 1.0 && h >= 1.0 && w <= f64::from(u32::MAX) && h <= f64::from(u32::MAX)) {
        return Err(LensError::Invalid(format!(
            "image size {w}x{h} out of range"
        )));
    }
    check_image_size(w.round() as u64, h.round() as u64).map_err(LensError::Invalid)?;
    let fx = match (lens.fl_x, lens.camera_angle_x) {
        (Some(f), _) => f,
        (None, Some(a)) => 0.5 * w / (0.5 * a).tan(),
        (None, None) => return Err(LensError::Invalid("no fl_x or camera_angle_x".into())),
    };
    let fy = match (lens.fl_y, lens.camera_angle_y) {
        (Some(f), _) => f,
        (None, Some(a)) => 0.5 * h / (0.5 * a).tan(),
        (None, None) => fx,
    };
    let cx = lens.cx.unwrap_or(0.5 * w);
    let cy = lens.cy.unwrap_or(0.5 * h);
    let coeffs = [lens.k1, lens.k2, lens.p1, lens.p2].map(|v| v.unwrap_or(0.0));
    if !(fx > 0.0 && fy > 0.0 && fx.is_finite() && fy.is_finite())
        || ![cx, cy].iter().chain(&coeffs).all(|v| v.is_finite())
    {
        return Err(LensError::Invalid(format!(
            "invalid intrinsics fx {fx} fy {fy} cx {cx} cy {cy} k1 k2 p1 p2 {coeffs:?}"
        )));
    }
    let intrinsics = Intrinsics {
        width: w.round() as u32,
        height: h.round() as u32,
        fx: fx as f32,
        fy: fy as f32,
        cx: cx as f32,
        cy: cy as f32,
    };
    let distortion = coeffs.iter().any(|&v| v != 0.0).then(|| Distortion {
        fx: fx as f32,
        fy: fy as f32,
        cx: cx as f32,
        cy: cy as f32,
        k1: coeffs[0] as f32,
        k2: coeffs[1] as f32,
        p1: coeffs[2] as f32,
        p2: coeffs[3] as f32,
    });
    let name = if distortion.is_some() {
        "OPENCV"
    } else {
        "PINHOLE"
    };
    Ok((intrinsics, distortion, name.to_owned()))
}

/// Camera counts per split, for reports.
pub fn split_counts(views: &[View]) -> BTreeMap<&'static str, usize> {
    let mut out = BTreeMap::new();
    for v in views {
        let key = match v.split {
            Split::Train => "train",
            Split::Test => "test",
            Split::Unspecified => "unspecified",
        };
        *out.entry(key).or_insert(0) += 1;
    }
    out
}
