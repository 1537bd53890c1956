//! A bad-input corpus for the dataset readers, generated here: truncated and bit-flipped COLMAP
//! `.bin` files, garbage text lines, counts that would allocate terabytes, missing images, unknown
//! camera models, empty points files, broken `transforms.json`. Each case must end in an error
//! (or the documented valid result) and none may panic: every call runs under `catch_unwind`.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use damage_twin::scene::colmap::{
    self, CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint,
};
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{Dataset, SceneError};

/// A small valid model: two cameras (PINHOLE, SIMPLE_RADIAL), three images with keypoints, four
/// points with tracks.
fn model() -> ColmapModel {
    let cameras = vec![
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
    let images = (1..=3u32)
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

/// A COLMAP dataset folder (`images/` with tiny PNGs, `sparse/0/` binary or text).
fn dataset(text: bool) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let sparse = tmp.path().join("sparse/0");
    if text {
        colmap::write_text(&sparse, &model()).unwrap();
    } else {
        colmap::write_binary(&sparse, &model()).unwrap();
    }
    std::fs::create_dir_all(tmp.path().join("images")).unwrap();
    for i in 1..=3 {
        image::RgbImage::new(8, 6)
            .save(tmp.path().join(format!("images/im{i}.png")))
            .unwrap();
    }
    tmp
}

fn open(root: &Path) -> Result<Dataset, SceneError> {
    Dataset::open(root, &OpenOptions::default())
}

/// Runs `f` and fails the test if it panics.
fn no_panic<T>(what: &str, f: impl FnOnce() -> T) -> T {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(v) => v,
        Err(_) => panic!("{what}: the reader panicked"),
    }
}

/// Opening must return an error whose message names `file` and contains `needle`.
fn must_fail(root: &Path, what: &str, file: &str, needle: &str) -> String {
    match no_panic(what, || open(root)) {
        Ok(_) => panic!("{what}: opened without error"),
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.contains(file),
                "{what}: error does not name {file}: {msg}"
            );
            assert!(
                msg.contains(needle),
                "{what}: expected {needle:?} in: {msg}"
            );
            msg
        }
    }
}

fn sparse_file(root: &Path, name: &str) -> PathBuf {
    root.join("sparse/0").join(name)
}

#[test]
fn the_generated_model_is_valid_in_both_encodings() {
    for text in [false, true] {
        let tmp = dataset(text);
        let ds = open(tmp.path()).unwrap();
        assert_eq!((ds.views.len(), ds.camera_count), (3, 2));
        assert_eq!(ds.points.map(|p| p.len()), Some(4));
        assert!(ds.warnings.is_empty(), "{:?}", ds.warnings);
    }
}

#[test]
fn every_truncation_of_every_bin_file_is_an_error() {
    let tmp = dataset(false);
    for name in ["cameras.bin", "images.bin", "points3D.bin"] {
        let path = sparse_file(tmp.path(), name);
        let full = std::fs::read(&path).unwrap();
        for len in 0..full.len() {
            std::fs::write(&path, &full[..len]).unwrap();
            must_fail(tmp.path(), &format!("{name} cut to {len} bytes"), name, "");
        }
        std::fs::write(&path, &full).unwrap();
    }
    // The zero-byte points3D.bin is truncated (no count), hence an error, covered above.
}

#[test]
fn random_bit_flips_never_panic_and_structural_flips_are_errors() {
    let tmp = dataset(false);
    let mut rng = fastrand::Rng::with_seed(0x5eed_2026);
    let (mut ok, mut err) = (0, 0);
    for name in ["cameras.bin", "images.bin", "points3D.bin"] {
        let path = sparse_file(tmp.path(), name);
        let full = std::fs::read(&path).unwrap();
        for _ in 0..700 {
            let mut bytes = full.clone();
            // One to three flipped bits anywhere.
            for _ in 0..rng.usize(1..=3) {
                let i = rng.usize(..bytes.len());
                bytes[i] ^= 1 << rng.u8(..8);
            }
            std::fs::write(&path, &bytes).unwrap();
            match no_panic(&format!("{name} flipped"), || open(tmp.path())) {
                Ok(_) => ok += 1,
                Err(_) => err += 1,
            }
        }
        std::fs::write(&path, &full).unwrap();
    }
    // A flip inside a float payload (a coordinate's mantissa) is a different valid model: only a
    // checksum could tell, and COLMAP's format has none. Flips in counts, ids and names fail.
    assert!(err > 300 && ok > 100, "{err} errors, {ok} valid");

    // Flips in a count's high bits always fail (the count outgrows the file).
    for name in ["cameras.bin", "images.bin", "points3D.bin"] {
        let path = sparse_file(tmp.path(), name);
        let full = std::fs::read(&path).unwrap();
        for bit in 20..64 {
            let mut bytes = full.clone();
            bytes[bit / 8] ^= 1 << (bit % 8);
            std::fs::write(&path, &bytes).unwrap();
            must_fail(
                tmp.path(),
                &format!("{name} count bit {bit}"),
                name,
                "count",
            );
        }
        std::fs::write(&path, &full).unwrap();
    }
}

#[test]
fn terabyte_counts_fail_before_allocating() {
    let tmp = dataset(false);
    // (file, byte offset of a u64 count): the file's record count, image 1's keypoint count
    // (after id 4, qvec+tvec 56, camera id 4, "im1.png\0" 8), point 1's track length
    // (after id 8, xyz 24, rgb 3, error 8).
    let cases = [
        ("cameras.bin", 0usize),
        ("images.bin", 0),
        ("points3D.bin", 0),
        ("images.bin", 8 + 4 + 56 + 4 + 8),
        ("points3D.bin", 8 + 8 + 24 + 3 + 8),
    ];
    for (name, offset) in cases {
        let path = sparse_file(tmp.path(), name);
        let full = std::fs::read(&path).unwrap();
        for count in [u64::MAX, 1 << 40, (full.len() as u64) * 10] {
            let mut bytes = full.clone();
            bytes[offset..offset + 8].copy_from_slice(&count.to_le_bytes());
            std::fs::write(&path, &bytes).unwrap();
            must_fail(
                tmp.path(),
                &format!("{name}@{offset} = {count}"),
                name,
                "count",
            );
        }
        std::fs::write(&path, &full).unwrap();
    }
    // Huge counts were refused, not reserved: the whole test process stays small.
    if let Some(mb) = damage_twin::metrics::peak_rss_mb() {
        assert!(mb < 2048.0, "peak RSS {mb} MB");
    }
}

#[test]
fn garbage_text_lines_are_errors_naming_file_and_line() {
    let cases: [(&str, &str, &str); 11] = [
        ("cameras.txt", "hello world\n", "camera id"),
        ("cameras.txt", "1 PINHOLE 8 6 7 7 4\n", "needs 4 parameters"),
        ("cameras.txt", "1 PINHOLE 8 six 7 7 4 3\n", "height"),
        (
            "cameras.txt",
            "1 PINHOLE 8 6 7 7 4 3 9\n",
            "needs 4 parameters",
        ),
        (
            "cameras.txt",
            "1 WEIRD_LENS 8 6 7 7 4 3\n",
            "unknown camera model \"WEIRD_LENS\"",
        ),
        ("images.txt", "1 0.9 0.1 -0.2 0.3 1 2\n\n", "missing"),
        (
            "images.txt",
            "9 1 0 0 0 0 0 0 1 im1.png\n1.0 2.0\n",
            "triples",
        ),
        (
            "images.txt",
            "9 1 0 0 0 0 0 0 1 im1.png\n1 2 x\n",
            "POINT3D_ID",
        ),
        ("points3D.txt", "1 0 0 0 300 0 0 0.5\n", "R (0-255)"),
        ("points3D.txt", "1 0 0 0 1 2 3 0.5 1\n", "pairs"),
        ("points3D.txt", "\u{1}\u{2}garbage\n", "point id"),
    ];
    for (name, line, needle) in cases {
        let tmp = dataset(true);
        let path = sparse_file(tmp.path(), name);
        let mut text = std::fs::read_to_string(&path).unwrap();
        text.push_str(line);
        std::fs::write(&path, text).unwrap();
        let msg = must_fail(tmp.path(), &format!("{name} + {line:?}"), name, needle);
        assert!(msg.contains("line "), "{msg}");
    }
    let tmp = dataset(true);
    std::fs::write(sparse_file(tmp.path(), "images.txt"), [0xff, 0xfe, b'\n']).unwrap();
    must_fail(tmp.path(), "non-UTF-8 images.txt", "images.txt", "UTF-8");
}

#[test]
fn unknown_and_unsupported_camera_models_are_refused() {
    let tmp = dataset(false);
    let path = sparse_file(tmp.path(), "cameras.bin");
    let mut bytes = std::fs::read(&path).unwrap();
    // First camera's model id follows the count (8) and the camera id (4).
    bytes[12..16].copy_from_slice(&99i32.to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    must_fail(
        tmp.path(),
        "model id 99",
        "cameras.bin",
        "unknown camera model id 99",
    );

    let tmp = dataset(false);
    let mut m = model();
    m.cameras[0] = ColmapCamera {
        model: CameraModel::OpenCvFisheye,
        params: vec![7.0, 7.0, 4.0, 3.0, 0.1, 0.0, 0.0, 0.0],
        ..m.cameras[0].clone()
    };
    colmap::write_binary(&tmp.path().join("sparse/0"), &m).unwrap();
    match no_panic("fisheye", || open(tmp.path())) {
        Err(e @ SceneError::Unsupported { .. }) => {
            assert!(e.to_string().contains("OPENCV_FISHEYE"), "{e}")
        }
        other => panic!("fisheye: expected Unsupported, got {other:?}"),
    }
}

#[test]
fn missing_images_warn_and_all_missing_is_an_error() {
    let tmp = dataset(false);
    std::fs::remove_file(tmp.path().join("images/im2.png")).unwrap();
    let ds = no_panic("one image missing", || open(tmp.path())).unwrap();
    assert_eq!(ds.views.len(), 2);
    assert!(
        ds.warnings
            .iter()
            .any(|w| w.contains("missing") && w.contains("im2.png")),
        "{:?}",
        ds.warnings
    );
    for i in [1, 3] {
        std::fs::remove_file(tmp.path().join(format!("images/im{i}.png"))).unwrap();
    }
    must_fail(
        tmp.path(),
        "all images missing",
        "images.bin",
        "no usable view",
    );
    std::fs::remove_dir(tmp.path().join("images")).unwrap();
    must_fail(
        tmp.path(),
        "no images folder",
        "images",
        "no images/ folder",
    );
}

#[test]
fn empty_points_files_zero_points_are_valid_zero_bytes_binary_is_not() {
    // Text: a points3D.txt with no lines is a valid model without points (COLMAP writes exactly
    // this, header comments only, for a reconstruction without points).
    let tmp = dataset(true);
    std::fs::write(sparse_file(tmp.path(), "points3D.txt"), "").unwrap();
    let ds = no_panic("empty points3D.txt", || open(tmp.path())).unwrap();
    assert!(ds.points.is_none());
    // Binary: a count of 0 is valid; zero bytes lacks even the count.
    let tmp = dataset(false);
    std::fs::write(sparse_file(tmp.path(), "points3D.bin"), 0u64.to_le_bytes()).unwrap();
    let ds = no_panic("zero-count points3D.bin", || open(tmp.path())).unwrap();
    assert!(ds.points.is_none());
    std::fs::write(sparse_file(tmp.path(), "points3D.bin"), []).unwrap();
    must_fail(
        tmp.path(),
        "zero-byte points3D.bin",
        "points3D.bin",
        "truncated",
    );
}

#[test]
fn inconsistent_models_are_errors() {
    let mut m = model();
    m.images[0].camera_id = 7;
    let tmp = dataset(false);
    colmap::write_binary(&tmp.path().join("sparse/0"), &m).unwrap();
    must_fail(tmp.path(), "undefined camera", "images.bin", "camera 7");

    let mut m = model();
    m.images[1].qvec = [0.0; 4];
    colmap::write_binary(&tmp.path().join("sparse/0"), &m).unwrap();
    must_fail(tmp.path(), "zero quaternion", "images.bin", "not finite");

    let mut m = model();
    m.cameras[1].params[0] = f64::NAN;
    colmap::write_binary(&tmp.path().join("sparse/0"), &m).unwrap();
    must_fail(
        tmp.path(),
        "NaN focal",
        "cameras.bin",
        "not a valid SIMPLE_RADIAL",
    );

    let mut m = model();
    m.cameras.push(m.cameras[0].clone());
    colmap::write_binary(&tmp.path().join("sparse/0"), &m).unwrap();
    must_fail(
        tmp.path(),
        "duplicate camera",
        "cameras.bin",
        "duplicate camera id 1",
    );

    let mut bytes = std::fs::read(sparse_file(tmp.path(), "cameras.bin")).unwrap();
    colmap::write_binary(&tmp.path().join("sparse/0"), &model()).unwrap();
    bytes = {
        let mut ok = std::fs::read(sparse_file(tmp.path(), "cameras.bin")).unwrap();
        ok.extend_from_slice(&bytes[..5]);
        ok
    };
    std::fs::write(sparse_file(tmp.path(), "cameras.bin"), bytes).unwrap();
    must_fail(
        tmp.path(),
        "trailing bytes",
        "cameras.bin",
        "trailing bytes",
    );
}

/// A NeRF-style folder with two frames and one 4×4 PNG.
fn transforms_dataset(json: &str) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(tmp.path().join("images")).unwrap();
    image::RgbImage::new(4, 4)
        .save(tmp.path().join("images/a.png"))
        .unwrap();
    std::fs::write(tmp.path().join("transforms.json"), json).unwrap();
    tmp
}

const IDENTITY: &str = "[[1,0,0,0],[0,1,0,0],[0,0,1,2],[0,0,0,1]]";

#[test]
fn broken_transforms_files_are_errors() {
    let frame = |path: &str, m: &str| format!(r#"{{"file_path":"{path}","transform_matrix":{m}}}"#);
    let ok = frame("images/a", IDENTITY);
    let cases = [
        ("{not json".to_owned(), "not a transforms file"),
        (r#"{"camera_angle_x":0.7}"#.to_owned(), "frames"),
        (
            format!(r#"{{"camera_angle_x":"wide","frames":[{ok}]}}"#),
            "not a transforms file",
        ),
        (
            format!(r#"{{"frames":[{ok}]}}"#),
            "no fl_x or camera_angle_x",
        ),
        (
            format!(
                r#"{{"camera_angle_x":0.7,"frames":[{}]}}"#,
                frame("images/a.png", "[[0,0,0,0],[0,0,0,0],[0,0,0,0],[0,0,0,1]]")
            ),
            "invertible",
        ),
        (
            format!(
                r#"{{"camera_angle_x":0.7,"frames":[{}]}}"#,
                frame("images/a.png", "[[1,0],[0,1]]")
            ),
            "4x4",
        ),
        (
            format!(
                r#"{{"camera_angle_x":0.7,"frames":[{}]}}"#,
                frame("images/gone.png", IDENTITY)
            ),
            "no usable view",
        ),
        (
            format!(r#"{{"fl_x":3,"w":4,"h":4,"camera_model":"OPENCV_FISHEYE","frames":[{ok}]}}"#),
            "unsupported",
        ),
        (
            format!(r#"{{"fl_x":3,"w":4,"h":4,"k3":0.2,"frames":[{ok}]}}"#),
            "k3",
        ),
        (
            format!(r#"{{"fl_x":-3,"w":4,"h":4,"frames":[{ok}]}}"#),
            "invalid intrinsics",
        ),
        (
            format!(r#"{{"fl_x":3,"w":1e300,"h":4,"frames":[{ok}]}}"#),
            "out of range",
        ),
        (
            format!(r#"{{"fl_x":3,"w":4,"h":4,"ply_file_path":"pts.ply","frames":[{ok}]}}"#),
            "",
        ),
    ];
    for (i, (json, needle)) in cases.iter().enumerate() {
        let tmp = transforms_dataset(json);
        if i == cases.len() - 1 {
            // A listed but absent ply is a warning; a present but broken one is an error.
            let ds = no_panic("absent ply", || open(tmp.path())).unwrap();
            assert!(
                ds.warnings.iter().any(|w| w.contains("pts.ply")),
                "{:?}",
                ds.warnings
            );
            std::fs::write(tmp.path().join("pts.ply"), "ply\nformat nonsense\n").unwrap();
            must_fail(tmp.path(), "broken ply", "pts.ply", "");
            continue;
        }
        let file = if needle.contains("no usable") {
            ""
        } else {
            "transforms.json"
        };
        must_fail(tmp.path(), &format!("case {i}: {json}"), file, needle);
    }
    // The well-formed file opens: extension appended, size read from the PNG.
    let tmp = transforms_dataset(&format!(r#"{{"camera_angle_x":0.7,"frames":[{ok}]}}"#));
    let ds = open(tmp.path()).unwrap();
    assert_eq!(ds.views[0].camera.intrinsics.width, 4);
}

#[test]
fn a_folder_that_is_no_dataset_is_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    must_fail(tmp.path(), "empty folder", "", "not a recognised dataset");
    std::fs::create_dir_all(tmp.path().join("sparse/0")).unwrap();
    must_fail(tmp.path(), "empty sparse", "sparse", "no COLMAP model");
    let missing = tmp.path().join("nope");
    must_fail(&missing, "missing path", "nope", "");
}
