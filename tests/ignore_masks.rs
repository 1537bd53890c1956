//! Ignore masks on real data (issue 26, §1): a copy of `opensfm_lund` with a block painted over
//! every training image trains far worse than the clean data; with ignore masks over the block
//! (`masks/<image file name>.png`, 0 = ignore) it trains to nearly the clean data's held-out
//! PSNR. 1/8 scale, 600 iterations, as the figures.

use std::path::{Path, PathBuf};

use damage_twin::damage::TrainMode;
use damage_twin::damage::setup::{RunConfig, prepare_run};
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::train::job::JobOptions;
use damage_twin::train::run::train;

fn lund() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/opensfm_lund")
}

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

/// A copy of lund whose training images have the middle quarter painted magenta; with `masks`,
/// each painted image has an ignore mask over the block. Held-out images stay clean.
fn painted_copy(dir: &Path, masks: bool) -> PathBuf {
    let src = lund();
    let root = dir.join(if masks { "masked" } else { "painted" });
    std::fs::create_dir_all(root.join("images")).unwrap();
    copy_dir(&src.join("sparse"), &root.join("sparse"));
    let clean = Dataset::open(&src, &OpenOptions::default()).expect("lund opens");
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
    let dir = tempfile::tempdir().unwrap();
    let painted = painted_copy(dir.path(), false);
    let masked = painted_copy(dir.path(), true);
    let opened = Dataset::open(&masked, &OpenOptions::default()).unwrap();
    assert_eq!(opened.ignore_mask_count(), opened.views.len() - 4);
    assert!(
        opened.mask_counts.is_empty(),
        "ignore masks are not damage masks: {:?}",
        opened.mask_counts
    );
    let clean = heldout_psnr(&lund());
    let without = heldout_psnr(&painted);
    let with = heldout_psnr(&masked);
    eprintln!("held-out PSNR: clean {clean:.2} dB, painted {without:.2} dB, masked {with:.2} dB");
    assert!(
        with >= without + 3.0,
        "masked {with:.2} vs painted {without:.2}"
    );
    assert!(with >= clean - 1.0, "masked {with:.2} vs clean {clean:.2}");
}
