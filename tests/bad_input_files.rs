//! The bad-input corpus for the files `scene` reads besides datasets (PLY, masks, images,
//! twin.ron), generated here. Every case must come back as an `Err` naming the file — not a
//! panic (checked with `catch_unwind`) and not a huge allocation (absurd counts fail early).

use std::collections::BTreeMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use damage_twin::scene::ply::read_point_cloud;
use damage_twin::scene::project::{PROJECT_FILE, PROJECT_FORMAT_VERSION, Project, Survey};
use damage_twin::scene::{
    Camera, Dataset, DatasetFormat, ImageScale, Intrinsics, SceneError, Split, View,
};
use damage_twin::splats::Splats;
use damage_twin::splats::ply::{read_splats, write_splats};
use glam::{Quat, Vec3};

/// Runs `f`, asserting it returns an error (not a panic) whose message contains every `needle`.
fn assert_fails<T: std::fmt::Debug>(
    case: &str,
    needles: &[&str],
    f: impl FnOnce() -> Result<T, SceneError>,
) {
    let result = catch_unwind(AssertUnwindSafe(f));
    let Ok(result) = result else {
        panic!("{case}: panicked instead of returning an error");
    };
    let err = match result {
        Ok(v) => panic!("{case}: accepted bad input: {v:?}"),
        Err(e) => e.to_string(),
    };
    for needle in needles {
        assert!(
            err.contains(needle),
            "{case}: error `{err}` lacks `{needle}`"
        );
    }
}

fn small_model() -> Splats {
    let mut s = Splats::empty(1, 3);
    for g in 0..5 {
        let sh: Vec<f32> = (0..12).map(|i| (g * 12 + i) as f32 * 0.01).collect();
        s.push(
            Vec3::splat(g as f32),
            Vec3::splat(-2.0),
            Quat::IDENTITY,
            0.5,
            &sh,
            &[0.1, 0.2, 0.3],
            g as u64,
            0,
        );
    }
    s
}

/// Offset of the data section and the row length of `small_model`'s file.
fn layout(bytes: &[u8]) -> (usize, usize) {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    // 3DGS floats (degree 1), 3 labels, survey; the double id; float damage_survey, uchar state.
    (end, 4 * (14 + 12 + 3 + 1) + 8 + 4 + 1)
}

#[test]
fn bad_ply_files_are_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.ply");
    write_splats(&good, &small_model()).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let (data, row) = layout(&bytes);
    let write = |name: &str, content: &[u8]| -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, content).unwrap();
        p
    };

    // NaN in x of vertex 3; +Inf in f_rest_0 of vertex 1.
    let mut nan = bytes.clone();
    nan[data + 3 * row..data + 3 * row + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let p = write("nan.ply", &nan);
    assert_fails("NaN", &["nan.ply", "vertex 3", "`x`"], || read_splats(&p));
    let mut inf = bytes.clone();
    let at = data + row + 9 * 4;
    inf[at..at + 4].copy_from_slice(&f32::INFINITY.to_le_bytes());
    let p = write("inf.ply", &inf);
    assert_fails("Inf", &["inf.ply", "vertex 1", "f_rest_0"], || {
        read_splats(&p)
    });

    // A required property renamed away (same byte layout, so only the name is missing).
    let text = String::from_utf8_lossy(&bytes[..data])
        .replace("property float opacity", "property float opacty");
    let mut missing = text.into_bytes();
    missing.extend_from_slice(&bytes[data..]);
    let p = write("missing.ply", &missing);
    assert_fails("missing property", &["missing.ply", "opacity"], || {
        read_splats(&p)
    });

    // f_rest count that is no SH degree.
    let text = String::from_utf8_lossy(&bytes[..data]).replace("property float f_rest_8\n", "");
    let mut rest = text.into_bytes();
    rest.extend_from_slice(&bytes[data..]);
    let p = write("rest.ply", &rest);
    assert_fails("f_rest count", &["rest.ply", "f_rest"], || read_splats(&p));

    // Truncated in the middle of vertex 4, and cut right after the header.
    let p = write("truncated.ply", &bytes[..data + 4 * row + 10]);
    assert_fails("truncated", &["truncated.ply"], || read_splats(&p));
    let p = write("header_only.ply", &bytes[..data]);
    assert_fails("header only", &["header_only.ply"], || read_splats(&p));

    // A vertex count that would need terabytes.
    let text = String::from_utf8_lossy(&bytes[..data])
        .replace("element vertex 5", "element vertex 99999999999999");
    let mut absurd = text.into_bytes();
    absurd.extend_from_slice(&bytes[data..]);
    let p = write("absurd.ply", &absurd);
    assert_fails("absurd count", &["absurd.ply", "99999999999999"], || {
        read_splats(&p)
    });
    let text =
        String::from_utf8_lossy(&bytes[..data]).replace("element vertex 5", "element vertex -5");
    let p = write("negative.ply", text.as_bytes());
    assert_fails("negative count", &["negative.ply"], || read_splats(&p));

    // Garbage: random bytes, an empty file, a header that never ends, an unknown format.
    let mut rng = fastrand::Rng::with_seed(7);
    let garbage: Vec<u8> = (0..4096).map(|_| rng.u8(..)).collect();
    let p = write("garbage.ply", &garbage);
    assert_fails("garbage", &["garbage.ply"], || read_splats(&p));
    let p = write("empty.ply", b"");
    assert_fails("empty file", &["empty.ply"], || read_splats(&p));
    let p = write(
        "endless.ply",
        b"ply\nformat binary_little_endian 1.0\ncomment x\n",
    );
    assert_fails("endless header", &["endless.ply", "end_header"], || {
        read_splats(&p)
    });
    let p = write(
        "format.ply",
        b"ply\nformat binary_middle_endian 1.0\nend_header\n",
    );
    assert_fails("unknown format", &["format.ply"], || read_splats(&p));
    let p = write("absent_dir_file.ply", b"");
    std::fs::remove_file(&p).unwrap();
    assert_fails("missing file", &["absent_dir_file.ply"], || read_splats(&p));

    // ASCII rows with too few values and with a word that is no number.
    let p = write(
        "ascii.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2    \n",
    );
    assert_fails("short ascii row", &["ascii.ply", "row 0"], || {
        read_point_cloud(&p)
    });
    let p = write(
        "ascii_word.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 two 3\n",
    );
    assert_fails("ascii word", &["ascii_word.ply", "two"], || {
        read_point_cloud(&p)
    });

    // Point clouds: no points, no positions, NaN position.
    let p = write(
        "no_points.ply",
        b"ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
    );
    assert_fails("empty cloud", &["no_points.ply", "no points"], || {
        read_point_cloud(&p)
    });
    let p = write(
        "no_z.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
    );
    assert_fails("cloud without z", &["no_z.ply", "`z`"], || {
        read_point_cloud(&p)
    });
    let p = write(
        "nan_points.ply",
        b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n1 nan 3\n",
    );
    assert_fails("NaN point", &["nan_points.ply", "vertex 1"], || {
        read_point_cloud(&p)
    });
}

fn write_grey(path: &Path, w: u32, h: u32) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::GrayImage::new(w, h).save(path).unwrap();
}

fn dataset(root: &Path, image: &Path, camera_size: (u32, u32)) -> Dataset {
    let intrinsics = Intrinsics {
        width: camera_size.0,
        height: camera_size.1,
        fx: 10.0,
        fy: 10.0,
        cx: camera_size.0 as f32 / 2.0,
        cy: camera_size.1 as f32 / 2.0,
    };
    Dataset {
        root: root.to_path_buf(),
        format: DatasetFormat::ColmapText,
        views: vec![View {
            name: "v".into(),
            image_path: image.to_path_buf(),
            camera: Camera::new(intrinsics, Quat::IDENTITY, Vec3::ZERO),
            distortion: None,
            split: Split::Unspecified,
            ignore_mask: None,
        }],
        image_files: 1,
        camera_count: 1,
        camera_models: BTreeMap::new(),
        points: None,
        masks: Some(damage_twin::scene::MaskFolder::shared(root.join("masks"))),
        mask_counts: BTreeMap::new(),
        background: [0.0; 3],
        warnings: Vec::new(),
        view_cache: None,
    }
}

#[test]
fn bad_images_and_masks_are_errors_naming_the_files() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let image = root.join("images/v.png");
    write_grey(&image, 16, 12);

    // Sanity: the good case loads, so the failures below are about the bad input.
    let ds = dataset(root, &image, (16, 12));
    let view = ds.load_view(0, ImageScale::Factor(2)).unwrap();
    assert_eq!((view.image.width, view.image.height), (8, 6));

    write_grey(&root.join("masks/spalling/v.png"), 15, 12);
    assert_fails(
        "wrong-size mask",
        &["masks/spalling/v.png", "images/v.png", "15×12", "16×12"],
        || ds.load_view(0, ImageScale::Factor(1)),
    );
    std::fs::remove_file(root.join("masks/spalling/v.png")).unwrap();

    // A colour-coded mask of the wrong size.
    std::fs::create_dir_all(root.join("masks")).unwrap();
    image::RgbImage::new(8, 8)
        .save(root.join("masks/v.png"))
        .unwrap();
    assert_fails(
        "wrong-size colour mask",
        &["masks/v.png", "images/v.png"],
        || ds.load_view(0, ImageScale::Factor(1)),
    );
    std::fs::write(root.join("masks/v.png"), b"not a png at all").unwrap();
    assert_fails("undecodable mask", &["masks/v.png"], || {
        ds.load_view(0, ImageScale::Factor(1))
    });
    std::fs::remove_file(root.join("masks/v.png")).unwrap();

    // Image and camera disagree (and not by a 2/4/8 downscale).
    let wrong = dataset(root, &image, (20, 12));
    assert_fails("image size", &["images/v.png", "16×12", "20×12"], || {
        wrong.load_view(0, ImageScale::Factor(1))
    });

    // A missing image file, a corrupt one, and a view index that does not exist.
    let missing = dataset(root, &root.join("images/gone.jpg"), (16, 12));
    assert_fails("missing image", &["images/gone.jpg"], || {
        missing.load_view(0, ImageScale::Factor(1))
    });
    let corrupt_path = root.join("images/corrupt.jpg");
    std::fs::write(&corrupt_path, [0xFF, 0xD8, 0xFF, 0xE0, 0, 16, b'J']).unwrap();
    let corrupt = dataset(root, &corrupt_path, (16, 12));
    assert_fails("corrupt image", &["images/corrupt.jpg"], || {
        corrupt.load_view(0, ImageScale::Factor(1))
    });
    assert_fails("view index", &["view 3"], || {
        ds.load_view(3, ImageScale::Factor(1))
    });
}

#[test]
fn bad_project_files_are_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(PROJECT_FILE);
    let mut project = Project::new();
    project
        .add_survey(Survey {
            name: "2024".into(),
            date: "2024-06-01".into(),
            dataset: "s1".into(),
            model: None,
            metrics: None,
            ..Default::default()
        })
        .unwrap();
    project.save(&path).unwrap();
    let good = std::fs::read_to_string(&path).unwrap();
    Project::load(&path).unwrap();

    let future = good.replacen(
        &format!("format_version: {PROJECT_FORMAT_VERSION}"),
        "format_version: 7",
        1,
    );
    assert_ne!(
        future, good,
        "the saved file spells format_version as expected"
    );
    std::fs::write(&path, &future).unwrap();
    assert_fails(
        "future version",
        &["twin.ron", "version 7", "newer"],
        || Project::load(&path),
    );

    for cut in [good.len() / 3, good.len() / 2, good.len() - 3] {
        std::fs::write(&path, &good[..cut]).unwrap();
        assert_fails("truncated twin.ron", &["twin.ron"], || Project::load(&path));
    }
    std::fs::write(&path, "").unwrap();
    assert_fails("empty twin.ron", &["twin.ron"], || Project::load(&path));
    std::fs::write(&path, [0xFFu8, 0xFE, 0x00, 0x41]).unwrap();
    assert_fails("binary twin.ron", &["twin.ron"], || Project::load(&path));
    let unordered = good.replace("2024-06-01", "2024-6-1");
    std::fs::write(&path, unordered).unwrap();
    assert_fails("bad date", &["twin.ron", "2024-6-1"], || {
        Project::load(&path)
    });
    std::fs::remove_file(&path).unwrap();
    assert_fails("missing twin.ron", &["twin.ron"], || Project::load(&path));
}
