//! The stamp tests' small posed capture (two walls seen by four photos through a SIMPLE_RADIAL
//! lens, k = 0.05), a crack photo with its mask to take shapes from, and a file-tree reader.

use std::path::{Path, PathBuf};

use damage_twin::scene::colmap::{
    CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint, write_text,
};
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::synth::stamp::StampParams;
use glam::Vec3;

pub const K1: f64 = 0.05;

/// Points on the wall z = 0 (x in [-3, 3], y in [-2, 2]) and on a side wall x = 3.
pub fn wall_points(rng: &mut fastrand::Rng) -> Vec<Vec3> {
    let mut points = Vec::new();
    for _ in 0..500 {
        points.push(Vec3::new(
            rng.f32() * 6.0 - 3.0,
            rng.f32() * 4.0 - 2.0,
            0.002 * rng.f32(),
        ));
    }
    for _ in 0..200 {
        points.push(Vec3::new(3.0, rng.f32() * 4.0 - 2.0, rng.f32() * 3.0));
    }
    points
}

/// A COLMAP text capture: four SIMPLE_RADIAL photos of textured noise looking at the wall from
/// z = 6, and `points` as its sparse points.
pub fn write_capture(root: &Path, points: &[Vec3]) -> Vec<Camera> {
    let k = Intrinsics {
        width: 320,
        height: 240,
        fx: 300.0,
        fy: 300.0,
        cx: 160.0,
        cy: 120.0,
    };
    std::fs::create_dir_all(root.join("images")).unwrap();
    let mut model = ColmapModel::default();
    model.cameras.push(ColmapCamera {
        id: 1,
        model: CameraModel::SimpleRadial,
        width: 320,
        height: 240,
        params: vec![300.0, 160.0, 120.0, K1],
    });
    let mut cameras = Vec::new();
    let mut rng = fastrand::Rng::with_seed(11);
    for (i, x) in [-1.5f32, -0.5, 0.5, 1.5].into_iter().enumerate() {
        let eye = Vec3::new(x, 0.2 * i as f32 - 0.3, 6.0);
        let camera = Camera::look_at(k, eye, Vec3::new(x * 0.4, 0.0, 0.0), -Vec3::Y);
        let name = format!("{i:02}.png");
        model
            .images
            .push(ColmapImage::from_camera(i as u32 + 1, 1, &name, &camera));
        let pixels: Vec<u8> = (0..320 * 240 * 3).map(|_| 60 + rng.u8(..120)).collect();
        image::RgbImage::from_raw(320, 240, pixels)
            .unwrap()
            .save(root.join("images").join(&name))
            .unwrap();
        cameras.push(camera);
    }
    model.points = points
        .iter()
        .enumerate()
        .map(|(i, p)| ColmapPoint {
            id: i as u64 + 1,
            xyz: p.as_dvec3().to_array(),
            rgb: [128; 3],
            error: 0.5,
            track: vec![(1, 0)],
        })
        .collect();
    write_text(&root.join("sparse/0"), &model).unwrap();
    cameras
}

/// A crack photo and its mask in the tunnel samples' layout (`1.png`, `1_m.png`): a wavy dark
/// line on grey (the test's own; the real sources are used on lund).
pub fn write_crack_source(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    let (w, h) = (200u32, 120u32);
    let mut photo = image::RgbImage::from_pixel(w, h, image::Rgb([150, 150, 145]));
    let mut mask = image::GrayImage::new(w, h);
    for x in 10..190 {
        let y = 60.0 + 20.0 * (x as f32 / 25.0).sin();
        for dy in -1..=1 {
            let yy = (y as i32 + dy) as u32;
            photo.put_pixel(x, yy, image::Rgb([40, 38, 35]));
            mask.put_pixel(x, yy, image::Luma([255]));
        }
    }
    photo.save(dir.join("1.png")).unwrap();
    mask.save(dir.join("1_m.png")).unwrap();
}

pub struct Fixture {
    _dir: tempfile::TempDir,
    pub capture: PathBuf,
    pub cracks: PathBuf,
    pub root: PathBuf,
}

pub fn fixture() -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().to_path_buf();
    let capture = root.join("capture");
    write_capture(&capture, &wall_points(&mut fastrand::Rng::with_seed(5)));
    let cracks = root.join("cracks");
    write_crack_source(&cracks);
    Fixture {
        _dir: dir,
        capture,
        cracks,
        root,
    }
}

pub fn params(f: &Fixture, out: &str, seed: u64) -> StampParams {
    StampParams {
        seed,
        metres_per_unit: Some(1.0),
        cracks: 3,
        spalls: 2,
        crack_length_m: 1.2,
        spall_diameter_m: 0.6,
        min_views: 2,
        ..StampParams::new(&f.capture, &f.root.join(out), vec![f.cracks.clone()])
    }
}

/// Every file under `dir` with its bytes, by relative path.
pub fn tree(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let bytes = std::fs::read(&path).unwrap();
                files.push((path.strip_prefix(dir).unwrap().to_path_buf(), bytes));
            }
        }
    }
    files.sort();
    files
}
