//! `segment` with the shared crack model (`../shared/data/crack_unet_crackpot`) against ONNX
//! Runtime and against crackforest's truth: tract's probabilities within 1e-3 per pixel of ONNX
//! Runtime's on three crackforest crops (`tests/fixtures/crack_unet/`, written once by its
//! `make_reference.py`), and the model's per-image mean IoU on crackforest at native size within
//! 0.02 of SOURCE.md's 0.39 (with precision and recall within 2 px near its 0.76 and 0.73).

mod shared_data;

use std::path::{Path, PathBuf};

use damage_twin::metrics::{MaskAgreement, NearAgreement};
use damage_twin::scene::DamageClass;
use damage_twin::scene::load::load_image;
use damage_twin::segment::{
    Photo, PhotoSettings, Preprocess, SegmentError, SegmentModel, SegmentSettings, Tiling,
    masks_from_probabilities, photo_probabilities, segment_photos,
};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/crack_unet")
        .join(name)
}

fn crack_model() -> Option<SegmentModel> {
    let path = shared_data::path("crack_unet_crackpot/crack_unet.onnx")?;
    Some(SegmentModel::open(&path, 1).expect("the shared crack model opens"))
}

/// The model run on the whole photo as it is (no scale, one tile): what ONNX Runtime was given.
fn native() -> PhotoSettings {
    PhotoSettings {
        preprocess: Preprocess::default(),
        scale: damage_twin::scene::ImageScale::Factor(1),
        tiling: Tiling::default(),
    }
}

/// A 16-bit grey PNG as values in [0, 1].
fn read_u16(path: &Path) -> (u32, u32, Vec<f32>) {
    let image = image::open(path).expect("reference PNG").into_luma16();
    let (w, h) = image.dimensions();
    let values = image
        .into_raw()
        .into_iter()
        .map(|v| f32::from(v) / 65535.0)
        .collect();
    (w, h, values)
}

#[test]
fn tract_matches_onnx_runtime_within_1e_3_per_pixel_on_crackforest_crops() {
    let Some(model) = crack_model() else { return };
    for name in ["001", "002", "003"] {
        let input = fixture(&format!("{name}_input.png"));
        let image = load_image(&input).unwrap();
        let maps = photo_probabilities(&model, &image, &input, &native()).unwrap();
        let (w, h, reference) = read_u16(&fixture(&format!("{name}_ort.png")));
        assert_eq!((maps[0].width, maps[0].height), (w, h));
        let worst = maps[0]
            .data
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        eprintln!("{name}: largest difference to ONNX Runtime {worst:.2e}");
        assert!(
            worst <= 1e-3,
            "{name}: tract differs from ONNX Runtime by {worst}"
        );
    }
}

/// IoU, precision and recall within 2 px of crackforest photo `i` at native size, counted as
/// SOURCE.md does (an image with nothing marked has precision 0).
fn crackforest_scores(model: &SegmentModel, i: usize) -> Option<[f64; 3]> {
    let photo = shared_data::path(&format!("crackforest/image/{i:03}.jpg"))?;
    let truth = shared_data::path(&format!("crackforest/masks/{i:03}.png"))?;
    let image = load_image(&photo).unwrap();
    let maps = photo_probabilities(model, &image, &photo, &native()).unwrap();
    let found: Vec<bool> = maps[0].data.iter().map(|&p| p >= 0.5).collect();
    let truth: Vec<bool> = damage_twin::scene::masks::read_binary_mask(&truth)
        .unwrap()
        .iter_bool()
        .collect();
    let mut agreement = MaskAgreement::default();
    agreement.accumulate(found.iter().copied(), truth.iter().copied());
    let near = NearAgreement::measure(
        &found,
        &truth,
        image.width as usize,
        image.height as usize,
        2,
    );
    let precision = if near.predicted == 0 {
        0.0
    } else {
        near.precision()
    };
    Some([agreement.iou(), precision, near.recall()])
}

/// ONNX Runtime's per-image figures (`crackforest_ort_scores.json`, by `make_reference.py`).
fn ort_scores() -> Vec<[f64; 3]> {
    let text = std::fs::read_to_string(fixture("crackforest_ort_scores.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["images"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| ["iou", "precision", "recall"].map(|k| s[k].as_f64().unwrap()))
        .collect()
}

/// The mean figures of tract on crackforest's first `count` photos, each checked within 0.02 of
/// ONNX Runtime's on the same photo.
fn crackforest_means(count: usize) -> Option<[f64; 3]> {
    let model = crack_model()?;
    let reference = ort_scores();
    let mut sums = [0.0; 3];
    for i in 1..=count {
        let scores = crackforest_scores(&model, i)?;
        for k in 0..3 {
            assert!(
                (scores[k] - reference[i - 1][k]).abs() <= 0.02,
                "{i:03}: tract {scores:?}, ONNX Runtime {:?}",
                reference[i - 1]
            );
            sums[k] += scores[k];
        }
    }
    Some(sums.map(|s| s / count as f64))
}

/// A subset in CI (the whole 20 take about a minute on a busy 2-core host): per photo, tract's
/// IoU and precision / recall within 2 px are ONNX Runtime's within 0.02.
#[test]
fn crackforest_scores_on_the_first_photos_are_onnx_runtimes() {
    let Some(means) = crackforest_means(4) else {
        return;
    };
    eprintln!("crackforest 001-004: IoU, precision, recall {means:.3?}");
}

/// SOURCE.md's figures on the first 20 photos at native size: IoU 0.39, precision 0.76 and
/// recall 0.73 within 2 px, each within 0.02. `cargo test --test segment_reference --
/// --ignored` (about a minute); `damage-twin study segment` reports the same figures.
#[test]
#[ignore = "a minute on a 2-core host; the subset above runs in CI"]
fn crackforest_iou_at_native_size_is_source_mds_figure() {
    let Some([iou, precision, recall]) = crackforest_means(20) else {
        return;
    };
    eprintln!("crackforest 001-020: IoU {iou:.3}, precision {precision:.3}, recall {recall:.3}");
    assert!((iou - 0.39).abs() <= 0.02, "IoU {iou}");
    assert!((precision - 0.76).abs() <= 0.02, "precision {precision}");
    assert!((recall - 0.73).abs() <= 0.02, "recall {recall}");
}

#[test]
fn a_model_read_with_the_wrong_class_count_is_refused_naming_the_shapes() {
    let Some(path) = shared_data::path("crack_unet_crackpot/crack_unet.onnx") else {
        return;
    };
    let err = SegmentModel::open(&path, 3).unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, SegmentError::Shape { .. }), "{text}");
    // Both shapes named: the model's [1, 1, …] output and the [1, 3, …] read for three classes.
    assert!(
        text.contains("crack_unet.onnx")
            && text.contains("output is [1,1,256,256]")
            && text.contains("reads [1, 3, 256, 256]"),
        "{text}"
    );
    assert!(!text.contains('\n'));
    let not_onnx = fixture("001_input.png");
    let err = SegmentModel::open(&not_onnx, 1).unwrap_err();
    assert!(matches!(err, SegmentError::Model { .. }), "{err}");
    assert!(err.to_string().contains("001_input.png") && !err.to_string().contains('\n'));
}

#[test]
fn tiles_at_half_scale_agree_with_the_whole_photo_and_probabilities_rethreshold() {
    let Some(model) = crack_model() else { return };
    let input = fixture("002_input.png");
    let image = load_image(&input).unwrap();
    let whole = photo_probabilities(&model, &image, &input, &native()).unwrap();
    let tiled_settings = PhotoSettings {
        tiling: Tiling {
            tile: 128,
            overlap: 32,
            multiple: 16,
        },
        ..native()
    };
    let tiled = photo_probabilities(&model, &image, &input, &tiled_settings).unwrap();
    let mut agreement = MaskAgreement::default();
    agreement.accumulate(
        tiled[0].data.iter().map(|&p| p >= 0.5),
        whole[0].data.iter().map(|&p| p >= 0.5),
    );
    eprintln!(
        "128-pixel tiles against the whole crop: IoU {:.3}",
        agreement.iou()
    );
    assert!(agreement.iou() > 0.8, "tiled IoU {}", agreement.iou());

    // The written masks are the stored probabilities thresholded: a rerun from them at the same
    // threshold rewrites the same files.
    let dir = tempfile::tempdir().unwrap();
    let photos = vec![Photo {
        name: "002".into(),
        path: input.clone(),
    }];
    let settings = SegmentSettings {
        classes: vec![Some(DamageClass::Crack)],
        photo: PhotoSettings {
            scale: damage_twin::scene::ImageScale::Factor(2),
            ..native()
        },
        threshold: 0.5,
        overwrite: false,
        background: [0.0; 3],
    };
    let summary = segment_photos(&model, dir.path(), &photos, &settings, &mut |_, _| true).unwrap();
    assert_eq!(summary.photos, 1);
    let mask_file = dir.path().join("masks/crack/002.png");
    let first = std::fs::read(&mask_file).unwrap();
    let written = damage_twin::scene::masks::read_binary_mask(&mask_file).unwrap();
    assert_eq!((written.width, written.height), (image.width, image.height));
    assert!(written.count() > 0);
    let again = segment_photos(&model, dir.path(), &photos, &settings, &mut |_, _| true);
    assert!(matches!(again, Err(SegmentError::Exists { .. })));
    masks_from_probabilities(dir.path(), &photos, &[DamageClass::Crack], 0.5).unwrap();
    assert_eq!(std::fs::read(&mask_file).unwrap(), first);
    let lower = masks_from_probabilities(dir.path(), &photos, &[DamageClass::Crack], 0.1).unwrap();
    assert!(lower.damage_fraction["crack"] >= summary.damage_fraction["crack"]);
}
