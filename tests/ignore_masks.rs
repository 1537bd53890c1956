//! Ignore masks on real data (issue 26, §1): a copy of `opensfm_lund` with a block painted over
//! every training image trains far worse than the clean data; with ignore masks over the block
//! (`masks/<image file name>.png`, 0 = ignore) it trains to nearly the clean data's held-out
//! PSNR. 1/8 scale, 600 iterations, as the issue's figures.

mod shared_data;

use std::path::{Path, PathBuf};

use damage_twin::damage::TrainMode;
use damage_twin::damage::setup::{RunConfig, prepare_run};
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::train::job::JobOptions;
use damage_twin::train::run::train;

fn config() -> RunConfig {
    RunConfig {
        mode: TrainMode::Rgb,
        scale: ImageScale::Factor(8),
        iterations: 600,
        seed: 5,
        ..RunConfig::default()
    }
}

fn heldout_psnr(root: &Path) -> f64 {
    let dataset = Dataset::open(root, &OpenOptions::default()).expect("opens");
    let run = prepare_run(&dataset, &config()).expect("prepares");
    let outcome = train(run.setup, JobOptions::default())
        .wait()
        .expect("trains");
    outcome.heldout.expect("held-out views").psnr
}

/// A copy of lund (`src`) whose training images have the middle quarter painted magenta; with
/// `masks`, each painted image has an ignore mask over the block. Held-out images stay clean.
fn painted_copy(src: &Path, dir: &Path, masks: bool) -> PathBuf {
    let root = dir.join(if masks { "masked" } else { "painted" });
    std::fs::create_dir_all(root.join("images")).unwrap();
    copy_dir(&src.join("sparse"), &root.join("sparse"));
    let clean = Dataset::open(src, &OpenOptions::default()).expect("lund opens");
    let heldout = prepare_run(&clean, &config())
        .expect("prepares")
        .heldout_indices;
    if masks {
        std::fs::create_dir_all(root.join("masks")).unwrap();
    }
    for entry in std::fs::read_dir(src.join("images")).unwrap() {
        let path = entry.unwrap().path();
        let file = path.file_name().unwrap().to_owned();
        let target = root.join("images").join(&file);
        let held = clean
            .views
            .iter()
            .enumerate()
            .any(|(i, v)| heldout.contains(&i) && v.image_path.file_name() == Some(&file));
        if held {
            std::fs::copy(&path, &target).unwrap();
            continue;
        }
        let mut image = image::open(&path).unwrap().to_rgb8();
        let (w, h) = image.dimensions();
        let (x0, y0, x1, y1) = (w / 4, h / 4, 3 * w / 4, 3 * h / 4);
        let mut ignore = image::GrayImage::from_pixel(w, h, image::Luma([255]));
        for y in y0..y1 {
            for x in x0..x1 {
                image.put_pixel(x, y, image::Rgb([230, 20, 200]));
                ignore.put_pixel(x, y, image::Luma([0]));
            }
        }
        image.save(&target).unwrap();
        if masks {
            let name = format!("{}.png", file.to_string_lossy());
            ignore.save(root.join("masks").join(name)).unwrap();
        }
    }
    root
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let path = entry.unwrap().path();
        let target = to.join(path.file_name().unwrap());
        if path.is_dir() {
            copy_dir(&path, &target);
        } else {
            std::fs::copy(&path, &target).unwrap();
        }
    }
}

#[test]
fn ignore_masks_keep_a_painted_block_out_of_training() {
    let Some(lund) = shared_data::path("opensfm_lund") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let painted = painted_copy(&lund, dir.path(), false);
    let masked = painted_copy(&lund, dir.path(), true);
    let opened = Dataset::open(&masked, &OpenOptions::default()).unwrap();
    assert_eq!(opened.ignore_mask_count(), opened.views.len() - 4);
    assert!(
        opened.mask_counts.is_empty(),
        "ignore masks are not damage masks: {:?}",
        opened.mask_counts
    );
    let clean = heldout_psnr(&lund);
    let without = heldout_psnr(&painted);
    let with = heldout_psnr(&masked);
    eprintln!("held-out PSNR: clean {clean:.2} dB, painted {without:.2} dB, masked {with:.2} dB");
    assert!(
        with >= without + 3.0,
        "masked {with:.2} vs painted {without:.2}"
    );
    assert!(with >= clean - 1.0, "masked {with:.2} vs clean {clean:.2}");
}

/// A two-frame nerfstudio dataset whose first frame names an ignore mask (`mask_path`), kept as
/// nerfstudio does in `masks/<stem>.png`; `missing` names a mask file that is not there.
fn nerfstudio_with_mask_path(dir: &Path, missing: bool) {
    std::fs::create_dir_all(dir.join("images")).unwrap();
    std::fs::create_dir_all(dir.join("masks")).unwrap();
    for name in ["f0", "f1"] {
        image::RgbImage::from_pixel(16, 12, image::Rgb([120, 90, 60]))
            .save(dir.join("images").join(format!("{name}.png")))
            .unwrap();
    }
    // Left half ignored (0), right half used (255).
    image::GrayImage::from_fn(16, 12, |x, _| image::Luma([if x < 8 { 0 } else { 255 }]))
        .save(dir.join("masks/f0.png"))
        .unwrap();
    let mask = if missing {
        "masks/none.png"
    } else {
        "masks/f0.png"
    };
    let m = |x: f32| format!("[[1,0,0,{x}],[0,1,0,0],[0,0,1,4],[0,0,0,1]]");
    let json = format!(
        r#"{{"fl_x":20,"fl_y":20,"cx":8,"cy":6,"w":16,"h":12,"frames":[
            {{"file_path":"images/f0.png","mask_path":"{mask}","transform_matrix":{}}},
            {{"file_path":"images/f1.png","transform_matrix":{}}}]}}"#,
        m(0.0),
        m(0.5)
    );
    std::fs::write(dir.join("transforms.json"), json).unwrap();
}

#[test]
fn nerfstudio_mask_path_is_the_frames_ignore_mask_not_a_damage_mask() {
    let dir = tempfile::tempdir().unwrap();
    nerfstudio_with_mask_path(dir.path(), false);
    let dataset = Dataset::open(dir.path(), &OpenOptions::default()).expect("opens");
    assert_eq!(dataset.ignore_mask_count(), 1);
    let f0 = dataset.view_index("f0").unwrap();
    let loaded = dataset.load_view(f0, ImageScale::Factor(1)).expect("loads");
    let ignore = loaded.ignore.expect("frame 0 has its mask_path");
    assert_eq!(ignore.data[0], 0, "left half ignored");
    assert_eq!(ignore.data[15], 1, "right half used");
    assert!(
        loaded.masks.is_empty(),
        "the ignore mask is not read as damage"
    );
    let f1 = dataset.view_index("f1").unwrap();
    assert!(
        dataset
            .load_view(f1, ImageScale::Factor(1))
            .unwrap()
            .ignore
            .is_none()
    );

    let dir = tempfile::tempdir().unwrap();
    nerfstudio_with_mask_path(dir.path(), true);
    let error = Dataset::open(dir.path(), &OpenOptions::default())
        .expect_err("a named mask that is missing is refused")
        .to_string();
    assert!(
        error.contains("transforms.json") && error.contains("mask_path"),
        "{error}"
    );
}

/// The viewer shows a photo's ignore mask when snapping to its view (ignored pixels dimmed
/// towards magenta), and the photo as it is with the setting off.
#[cfg(feature = "app")]
#[test]
fn the_viewer_dims_the_ignored_part_of_a_snapped_photo() {
    use damage_twin::app::commands::Command;
    use damage_twin::app::settings::Settings;
    use damage_twin::app::state::{AppState, Photo};
    let dir = tempfile::tempdir().unwrap();
    nerfstudio_with_mask_path(dir.path(), false);
    for show in [true, false] {
        let mut state = AppState::new(Settings {
            show_ignore_masks: show,
            ..Settings::default()
        });
        state.apply(Command::Open(dir.path().to_path_buf()));
        let start = std::time::Instant::now();
        while state.scene.is_none() {
            state.poll();
            assert!(start.elapsed().as_secs() < 10, "{:?}", state.log);
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let f0 = state
            .scene
            .as_ref()
            .unwrap()
            .dataset
            .as_ref()
            .unwrap()
            .view_index("f0");
        state.apply(Command::SnapToView(f0.unwrap()));
        let photo = loop {
            state.poll();
            if let Some(Photo::Loaded(image)) = state.snap.as_ref().map(|s| s.photo.clone()) {
                break image;
            }
            assert!(start.elapsed().as_secs() < 10, "{:?}", state.log);
            std::thread::sleep(std::time::Duration::from_millis(5));
        };
        let (left, right) = (&photo.data[0..3], &photo.data[15 * 3..16 * 3]);
        assert!(
            (right[0] - 120.0 / 255.0).abs() < 0.01,
            "used pixels as they are"
        );
        if show {
            assert!(left[1] < right[1] * 0.5, "ignored pixels dimmed: {left:?}");
            assert!(left[2] > left[1], "and tinted magenta: {left:?}");
        } else {
            assert_eq!(left, right, "the photo as it is");
        }
    }
}
