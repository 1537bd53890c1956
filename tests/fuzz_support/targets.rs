//! The fuzz harness's targets: per reader a folder of small valid inputs (built here, plus two
//! small real files from `../shared/data/crackforest`), the files a case mutates and how the
//! case is read back through the public API.

use std::path::{Path, PathBuf};

use damage_twin::scene::colmap::{
    self, CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint,
};
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::ply::{read_point_cloud, read_point_cloud_skipping, write_point_cloud};
use damage_twin::scene::project::{PROJECT_FILE, Project, Survey};
use damage_twin::scene::{Dataset, ImageScale, PointCloud, SceneError};
use damage_twin::splats::Splats;
use damage_twin::splats::ply::{read_splats, write_splats};
use glam::{Quat, Vec3};

use super::mutate::Content;

/// `E`: what a failed read returns (the scene readers' `SceneError`; a project's reads return
/// several error types, kept as their messages).
pub struct Target<E = SceneError> {
    pub name: &'static str,
    pub dir: tempfile::TempDir,
    /// Files (relative to `dir`) a case mutates, one per case, with their valid bytes.
    pub seeds: Vec<(PathBuf, Vec<u8>, Content)>,
    /// Reads the case: the folder and the mutated file.
    pub read: fn(&Path, &Path) -> Result<(), E>,
}

pub fn seed(dir: &Path, rel: &str, content: Content) -> (PathBuf, Vec<u8>, Content) {
    let bytes = std::fs::read(dir.join(rel)).unwrap_or_else(|e| panic!("seed {rel}: {e}"));
    (PathBuf::from(rel), bytes, content)
}

/// Opens the dataset and loads its first two views at two scales (pixels, masks, undistortion).
pub fn open_and_load(root: &Path, _: &Path) -> Result<(), SceneError> {
    let ds = Dataset::open(root, &OpenOptions::default())?;
    for index in 0..ds.views.len().min(2) {
        ds.load_view(index, ImageScale::Factor(1))?;
        ds.load_view(index, ImageScale::Factor(2))?;
    }
    Ok(())
}

/// Two cameras (PINHOLE, SIMPLE_RADIAL) of 8 × 6, three images with keypoints, four points.
pub fn colmap_model(real_jpeg: Option<(u32, u32)>) -> ColmapModel {
    let mut cameras = vec![
        ColmapCamera {
            id: 1,
            model: CameraModel::Pinhole,
            width: 8,
            height: 6,
            params: vec![7.0, 7.5, 4.0, 3.0],
        },
        ColmapCamera {
            id: 2,
            model: CameraModel::SimpleRadial,
            width: 8,
            height: 6,
            params: vec![7.0, 4.0, 3.0, 0.01],
        },
    ];
    let mut images: Vec<ColmapImage> = (1..=3u32)
        .map(|i| ColmapImage {
            id: i,
            qvec: [0.9, 0.1 * i as f64, -0.2, 0.3],
            tvec: [i as f64, -1.5, 4.25],
            camera_id: 1 + i % 2,
            name: format!("im{i}.png"),
            points2d: (0..i as i64)
                .map(|k| ([k as f64 + 0.5, 2.25], if k == 0 { -1 } else { k }))
                .collect(),
        })
        .collect();
    if let Some((w, h)) = real_jpeg {
        cameras.push(ColmapCamera {
            id: 3,
            model: CameraModel::SimplePinhole,
            width: w.into(),
            height: h.into(),
            params: vec![w as f64, w as f64 / 2.0, h as f64 / 2.0],
        });
        images.push(ColmapImage {
            id: 4,
            qvec: [1.0, 0.0, 0.0, 0.0],
            tvec: [0.0, 0.0, 3.0],
            camera_id: 3,
            name: "real.jpg".into(),
            points2d: Vec::new(),
        });
    }
    let points = (1..=4u64)
        .map(|i| ColmapPoint {
            id: i,
            xyz: [i as f64, 0.5, -2.0],
            rgb: [10 * i as u8, 20, 30],
            error: 0.25,
            track: vec![(1, 0), (2, i as u32 % 2)],
        })
        .collect();
    ColmapModel {
        cameras,
        images,
        points,
    }
}

/// `images/im1..3.png`: RGB, RGBA and 16-bit grey, 8 × 6.
pub fn write_images(root: &Path) {
    std::fs::create_dir_all(root.join("images")).unwrap();
    image::RgbImage::from_fn(8, 6, |x, y| image::Rgb([x as u8 * 30, y as u8 * 40, 90]))
        .save(root.join("images/im1.png"))
        .unwrap();
    image::RgbaImage::from_fn(8, 6, |x, y| {
        image::Rgba([200, x as u8 * 20, 10, y as u8 * 50])
    })
    .save(root.join("images/im2.png"))
    .unwrap();
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(8, 6, |x, y| {
        image::Luma([(x * 8000 + y * 300) as u16])
    })
    .save(root.join("images/im3.png"))
    .unwrap();
}

pub fn colmap_target(name: &'static str, text: bool) -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let sparse = root.join("sparse/0");
    if text {
        colmap::write_text(&sparse, &colmap_model(None)).unwrap();
    } else {
        colmap::write_binary(&sparse, &colmap_model(None)).unwrap();
    }
    write_images(root);
    let (ext, content) = if text {
        ("txt", Content::Text)
    } else {
        ("bin", Content::Binary)
    };
    let seeds = ["cameras", "images", "points3D"]
        .map(|f| seed(root, &format!("sparse/0/{f}.{ext}"), content))
        .into();
    Target {
        name,
        dir,
        seeds,
        read: open_and_load,
    }
}

/// A COLMAP dataset whose image files are mutated: the three PNGs and a real 28 KB JPEG (`None`,
/// the test skips, without the shared data).
pub fn images_target() -> Option<Target> {
    let jpeg = crate::shared_data::path("crackforest/image/060.jpg")?;
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    write_images(root);
    std::fs::copy(&jpeg, root.join("images/real.jpg")).unwrap();
    let size = image::image_dimensions(&jpeg).unwrap();
    colmap::write_text(&root.join("sparse/0"), &colmap_model(Some(size))).unwrap();
    let seeds = ["im1.png", "im2.png", "im3.png", "real.jpg"]
        .map(|f| seed(root, &format!("images/{f}"), Content::Binary))
        .into();
    Some(Target {
        name: "images",
        dir,
        seeds,
        read: |root, mutated| {
            let open_and_load_all = || {
                let ds = Dataset::open(root, &OpenOptions::default())?;
                for index in 0..ds.views.len() {
                    ds.load_view(index, ImageScale::Factor(1))?;
                    ds.load_view(index, ImageScale::Width(3))?;
                }
                Ok(())
            };
            first_error([
                damage_twin::scene::load::load_image(mutated).map(drop),
                open_and_load_all(),
            ])
        },
    })
}

/// A dataset with per-class and colour-coded masks, and a real crackforest mask read on its own
/// (its 480 × 320 fits no view here); `None` (the test skips) without the shared data.
pub fn masks_target() -> Option<Target> {
    let real_mask = crate::shared_data::path("crackforest/masks/060.png")?;
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    write_images(root);
    colmap::write_binary(&root.join("sparse/0"), &colmap_model(None)).unwrap();
    let masks = root.join("masks");
    std::fs::create_dir_all(masks.join("crack")).unwrap();
    std::fs::create_dir_all(masks.join("spalling")).unwrap();
    image::GrayImage::from_fn(8, 6, |x, y| image::Luma([if x == y { 255 } else { 0 }]))
        .save(masks.join("crack/im1.png"))
        .unwrap();
    // 0/1-valued, as numpy writes masks without scaling.
    image::GrayImage::from_fn(8, 6, |x, _| image::Luma([u8::from(x > 4)]))
        .save(masks.join("spalling/im2.png"))
        .unwrap();
    image::RgbImage::from_fn(8, 6, |x, _| match x {
        0 => image::Rgb([255, 0, 0]),
        1 => image::Rgb([255, 192, 203]),
        2 => image::Rgb([255, 255, 50]),
        _ => image::Rgb([0, 0, 0]),
    })
    .save(masks.join("im1.png"))
    .unwrap();
    std::fs::copy(real_mask, root.join("real_mask.png")).unwrap();
    let seeds = [
        "masks/crack/im1.png",
        "masks/spalling/im2.png",
        "masks/im1.png",
        "real_mask.png",
    ]
    .map(|f| seed(root, f, Content::Binary))
    .into();
    Some(Target {
        name: "masks",
        dir,
        seeds,
        read: |root, mutated| {
            use damage_twin::scene::masks::{default_palette, read_binary_mask, read_colour_mask};
            let views = || {
                let ds = Dataset::open(root, &OpenOptions::default())?;
                for index in 0..ds.views.len().min(2) {
                    ds.load_view(index, ImageScale::Factor(1))?;
                    ds.load_view(index, ImageScale::Factor(4))?;
                }
                Ok(())
            };
            // Root-level masks are colour-coded; the others are per-class binary masks.
            let colour_coded = mutated.parent() == Some(root.join("masks").as_path());
            let direct = if colour_coded {
                read_colour_mask(mutated, &default_palette()).map(drop)
            } else {
                read_binary_mask(mutated).map(drop)
            };
            first_error([direct, views()])
        },
    })
}

/// A `transforms.json` dataset in `root`: the three images, a point cloud, frames with
/// distortion, per-frame intrinsics and a 3×4 matrix.
pub fn write_transforms_dataset(root: &Path) {
    write_images(root);
    let cloud = PointCloud {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(0.5, 0.5, 0.5)],
        colours: vec![[255, 0, 0], [0, 255, 0], [0, 0, 255]],
    };
    write_point_cloud(&root.join("points.ply"), &cloud).unwrap();
    let json = r#"{
  "camera_angle_x": 0.69,
  "w": 8,
  "h": 6,
  "k1": 0.01,
  "ply_file_path": "points.ply",
  "frames": [
    {"file_path": "images/im1.png", "transform_matrix": [[1, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]},
    {"file_path": "images/im2", "fl_x": 7.5, "transform_matrix": [[0, 0, 1, 4], [0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1]]},
    {"file_path": "./images/im3.png", "w": 8, "h": 6, "cx": 4.2, "transform_matrix": [[1, 0, 0, 0], [0, 0, -1, -4], [0, 1, 0, 0]]}
  ]
}
"#;
    std::fs::write(root.join("transforms.json"), json).unwrap();
}

pub fn transforms_target() -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    write_transforms_dataset(root);
    let seeds = vec![
        seed(root, "transforms.json", Content::Text),
        seed(root, "points.ply", Content::Binary),
    ];
    Target {
        name: "transforms",
        dir,
        seeds,
        read: open_and_load,
    }
}

/// A model with SH degree 1 and three label channels, as written (binary little-endian), and
/// the same values as ASCII and big-endian PLY.
pub fn ply_splats_target() -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let mut splats = Splats::empty(1, 3);
    for g in 0..4 {
        let sh: Vec<f32> = (0..12).map(|i| (g * 12 + i) as f32 * 0.01 - 0.2).collect();
        splats.push(
            Vec3::new(g as f32, -0.5 * g as f32, 1.0),
            Vec3::splat(-2.0 + 0.1 * g as f32),
            Quat::from_xyzw(0.1, 0.2, 0.3, 0.9),
            0.5,
            &sh,
            &[0.1, -0.2, 0.3],
            10 + g as u64,
            g as u16 % 2,
        );
    }
    write_splats(&root.join("model.ply"), &splats).unwrap();
    let binary = std::fs::read(root.join("model.ply")).unwrap();
    let end = binary
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = String::from_utf8(binary[..end].to_vec()).unwrap();
    // Each row's scalars in header order, by their declared sizes (floats, the double id,
    // the uchar state bits): the ASCII and big-endian copies are written property by property.
    let sizes: Vec<usize> = header
        .lines()
        .filter_map(
            |line| match line.split_whitespace().collect::<Vec<_>>()[..] {
                ["property", "float", _] => Some(4),
                ["property", "double", _] => Some(8),
                ["property", "uchar", _] => Some(1),
                ["property", ty, name] => panic!("property {name} has a type {ty} this seed lacks"),
                _ => None,
            },
        )
        .collect();
    let row = sizes.iter().sum::<usize>();
    assert_eq!(
        row * splats.len(),
        binary.len() - end,
        "rows match the header"
    );
    let mut ascii = header.replace("binary_little_endian", "ascii");
    let mut big = header
        .replace("binary_little_endian", "binary_big_endian")
        .into_bytes();
    for r in binary[end..].chunks_exact(row) {
        let mut values = Vec::with_capacity(sizes.len());
        let mut at = 0;
        for &size in &sizes {
            let bytes = &r[at..at + size];
            values.push(match size {
                4 => f32::from_le_bytes(bytes.try_into().unwrap()).to_string(),
                8 => f64::from_le_bytes(bytes.try_into().unwrap()).to_string(),
                _ => bytes[0].to_string(),
            });
            big.extend(bytes.iter().rev());
            at += size;
        }
        ascii.push_str(&values.join(" "));
        ascii.push('\n');
    }
    std::fs::write(root.join("ascii.ply"), ascii).unwrap();
    std::fs::write(root.join("big.ply"), big).unwrap();
    for name in ["ascii.ply", "big.ply"] {
        assert_eq!(read_splats(&root.join(name)).unwrap(), splats, "{name}");
    }
    let seeds = vec![
        seed(root, "model.ply", Content::Binary),
        seed(root, "ascii.ply", Content::Text),
        seed(root, "big.ply", Content::Binary),
    ];
    Target {
        name: "ply_splats",
        dir,
        seeds,
        read: |_, mutated| read_splats(mutated).map(drop),
    }
}

/// The SPZ reader: files of versions 3 and 2 (mutations mostly break the gzip stream), and the
/// decompressed payload, which the case gzips before decoding so that header lies, short
/// attribute blocks and odd values reach the decoder itself.
pub fn spz_target() -> Target {
    use damage_twin::splats::spz::{SpzOptions, SpzVersion, read_spz, write_spz};
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let mut splats = Splats::empty(2, 0);
    for g in 0..5 {
        let sh: Vec<f32> = (0..27).map(|i| (g * 27 + i) as f32 * 0.004 - 0.2).collect();
        splats.push(
            Vec3::new(g as f32, -0.5 * g as f32, 1.0),
            Vec3::splat(-2.0 + 0.1 * g as f32),
            Quat::from_xyzw(0.1 * g as f32, 0.2, -0.3, 0.9).normalize(),
            0.5,
            &sh,
            &[],
            10 + g as u64,
            0,
        );
    }
    for (name, version) in [("v3.spz", SpzVersion::V3), ("v2.spz", SpzVersion::V2)] {
        write_spz(&root.join(name), &splats, &SpzOptions::new(version)).unwrap();
    }
    let compressed = std::fs::read(root.join("v3.spz")).unwrap();
    let mut payload = Vec::new();
    std::io::Read::read_to_end(
        &mut flate2::read::GzDecoder::new(compressed.as_slice()),
        &mut payload,
    )
    .unwrap();
    std::fs::write(root.join("payload.bin"), payload).unwrap();
    let seeds = vec![
        seed(root, "v3.spz", Content::Binary),
        seed(root, "v2.spz", Content::Binary),
        seed(root, "payload.bin", Content::Binary),
    ];
    Target {
        name: "spz",
        dir,
        seeds,
        read: |dir, mutated| {
            let path = if mutated.extension().is_some_and(|e| e == "bin") {
                let raw = std::fs::read(mutated).map_err(|e| SceneError::io(mutated, e))?;
                let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
                std::io::Write::write_all(&mut gz, &raw).unwrap();
                let path = dir.join("payload.spz");
                std::fs::write(&path, gz.finish().unwrap()).unwrap();
                path
            } else {
                mutated.to_path_buf()
            };
            read_spz(&path).map(drop).map_err(|e| match e {
                damage_twin::splats::spz::SpzError::File(e) => e,
                other => SceneError::invalid(mutated, other.to_string()),
            })
        },
    }
}

pub fn ply_points_target() -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let cloud = PointCloud {
        positions: (0..6)
            .map(|i| Vec3::new(i as f32, 0.5, -0.25 * i as f32))
            .collect(),
        colours: (0..6).map(|i| [i as u8 * 40, 100, 200]).collect(),
    };
    write_point_cloud(&root.join("binary.ply"), &cloud).unwrap();
    std::fs::write(
        root.join("ascii.ply"),
        "ply\nformat ascii 1.0\ncomment Open3D float colours\nelement vertex 3\n\
         property double x\nproperty double y\nproperty double z\nproperty float red\n\
         property float green\nproperty float blue\nelement face 0\n\
         property list uchar int vertex_indices\nend_header\n\
         0 0 0 1 0 0\n1.5 -2 3 0 1 0\n0.25 0.5 0.75 0 0 1\n",
    )
    .unwrap();
    let seeds = vec![
        seed(root, "binary.ply", Content::Binary),
        seed(root, "ascii.ply", Content::Text),
    ];
    Target {
        name: "ply_points",
        dir,
        seeds,
        read: |_, mutated| {
            let strict = read_point_cloud(mutated);
            let lenient = read_point_cloud_skipping(mutated);
            // The two differ only in skipping: what the strict reader accepts, the lenient one
            // reads identically without skipping anything.
            if let Ok(cloud) = &strict {
                let (same, skipped) = lenient.as_ref().expect("lenient fails where strict reads");
                assert!(skipped.is_empty() && same == cloud);
            }
            first_error([lenient.map(drop), strict.map(drop)])
        },
    }
}

pub fn project_target() -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let mut project = Project::new();
    for (name, date) in [("before", "2024-03-01"), ("after", "2024-09-15")] {
        project
            .add_survey(Survey {
                name: name.into(),
                date: date.into(),
                dataset: format!("surveys/{name}").into(),
                model: Some(format!("surveys/{name}/model.ply").into()),
                metrics: None,
                ..Default::default()
            })
            .unwrap();
    }
    project.settings.scale = ImageScale::Width(960);
    project.save(&root.join(PROJECT_FILE)).unwrap();
    let seeds = vec![seed(root, PROJECT_FILE, Content::Text)];
    Target {
        name: "twin_ron",
        dir,
        seeds,
        read: |_, mutated| Project::load(mutated).map(drop),
    }
}

/// The first error of several reads that all ran.
pub fn first_error<const N: usize>(results: [Result<(), SceneError>; N]) -> Result<(), SceneError> {
    results.into_iter().collect()
}
