//! `damage-twin pose`: COLMAP driven on photos, the dataset it writes, and its refusals. The
//! error paths use a fake `colmap` on PATH (a shell script) so they run everywhere; the run on
//! the synthetic building needs Debian's `colmap`, and skips with one line where it is missing —
//! except in CI (`DAMAGE_TWIN_REQUIRE_SHARED_DATA=1`, set by `.ci/run`, which installs it).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{Camera, Dataset};
use damage_twin::synth::SynthParams;
use glam::DVec3;

fn binary() -> Command {
    Command::new(env!("CARGO_BIN_EXE_damage-twin"))
}

/// `count` small textured PNG photos (random noise) in `dir`.
fn noise_photos(dir: &Path, count: usize) {
    std::fs::create_dir_all(dir).unwrap();
    let mut rng = fastrand::Rng::with_seed(9);
    for i in 0..count {
        let img = image::RgbImage::from_fn(64, 48, |_, _| {
            image::Rgb([rng.u8(..), rng.u8(..), rng.u8(..)])
        });
        img.save(dir.join(format!("{i:02}.png"))).unwrap();
    }
}

/// A folder holding only a fake `colmap` running `script` (sh).
fn fake_colmap(dir: &Path, script: &str) -> PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let bin = dir.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let path = bin.join("colmap");
    std::fs::write(&path, format!("#!/bin/sh\n{script}\n")).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    bin
}

fn pose(photos: &Path, out: &Path, path_env: &Path) -> Output {
    binary()
        .args(["pose", "--quiet"])
        .arg(photos)
        .arg("--out")
        .arg(out)
        .env("PATH", path_env)
        .env_remove("DAMAGE_TWIN_COLMAP")
        .output()
        .unwrap()
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Nothing named like the dataset, and no staging folder, is left in `parent`.
fn assert_no_dataset(parent: &Path, name: &str) {
    let left: Vec<String> = std::fs::read_dir(parent)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(name) && !n.ends_with(".pose-failed.log"))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn a_missing_colmap_names_the_package_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    noise_photos(&dir.path().join("photos"), 3);
    let empty = dir.path().join("empty-bin");
    std::fs::create_dir_all(&empty).unwrap();
    let out = pose(&dir.path().join("photos"), &dir.path().join("ds"), &empty);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("apt-get install colmap"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert_no_dataset(dir.path(), "ds");
}

#[test]
fn one_photo_is_refused_before_colmap_runs() {
    let dir = tempfile::tempdir().unwrap();
    noise_photos(&dir.path().join("photos"), 1);
    let bin = fake_colmap(dir.path(), "echo ran >> \"$0.calls\"; exit 0");
    let out = pose(&dir.path().join("photos"), &dir.path().join("ds"), &bin);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("1 photo(s)") && err.contains("at least 2"),
        "{err}"
    );
    assert!(!bin.join("colmap.calls").exists(), "COLMAP ran");
    assert_no_dataset(dir.path(), "ds");
}

#[test]
fn a_crashing_colmap_reports_the_command_and_its_last_lines() {
    let dir = tempfile::tempdir().unwrap();
    noise_photos(&dir.path().join("photos"), 3);
    // Extraction works; the matcher crashes after a few lines.
    let bin = fake_colmap(
        dir.path(),
        "case \"$1\" in\n  *_matcher) echo 'Matching image [1/3]'; echo 'F0101 boom.cc:1] Check failed: \
         matches' >&2; exit 134;;\n  *) echo 'Processed file [3/3]'; exit 0;;\nesac",
    );
    let out = pose(&dir.path().join("photos"), &dir.path().join("ds"), &bin);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("exhaustive_matcher --database_path"), "{err}");
    assert!(err.contains("Check failed: matches"), "{err}");
    assert!(err.contains("exit status: 134"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert_no_dataset(dir.path(), "ds");
    // The full log is kept beside, under a name no one takes for a dataset.
    let log = std::fs::read_to_string(dir.path().join("ds.pose-failed.log")).unwrap();
    assert!(
        log.contains("$ ") && log.contains("feature_extractor"),
        "{log}"
    );
}

#[test]
fn photos_that_do_not_overlap_are_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    noise_photos(&dir.path().join("photos"), 4);
    // COLMAP's mapper finds no initial pair: it says so and writes no model.
    let bin = fake_colmap(
        dir.path(),
        "case \"$1\" in\n  mapper) echo '  => No good initial image pair found.'; \
         echo 'ERROR: failed to create sparse model' >&2; exit 1;;\n  *) exit 0;;\nesac",
    );
    let out = pose(&dir.path().join("photos"), &dir.path().join("ds"), &bin);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("do not overlap"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert_no_dataset(dir.path(), "ds");
}

/// Debian's `colmap`, or `None` (with the skip line) where it is missing and not required.
fn real_colmap() -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    if let Some(found) = std::env::split_paths(&path)
        .map(|d| d.join("colmap"))
        .find(|p| p.is_file())
    {
        return Some(found);
    }
    if std::env::var("DAMAGE_TWIN_REQUIRE_SHARED_DATA").is_ok_and(|v| v == "1") {
        panic!("colmap is not installed, and DAMAGE_TWIN_REQUIRE_SHARED_DATA=1 (CI installs it)");
    }
    eprintln!("skipped: colmap not installed (apt-get install colmap)");
    None
}

/// Median rotation error (degrees) and median centre error (fraction of the known centres'
/// extent) of `posed` against `known` (matched by image name) after the best similarity.
fn pose_errors(known: &[(String, Camera)], posed: &[(String, Camera)]) -> (f64, f64, usize) {
    let pairs: Vec<(&Camera, &Camera)> = posed
        .iter()
        .filter_map(|(n, c)| known.iter().find(|(k, _)| k == n).map(|(_, k)| (c, k)))
        .collect();
    let from: Vec<DVec3> = pairs.iter().map(|(p, _)| p.position().as_dvec3()).collect();
    let to: Vec<DVec3> = pairs.iter().map(|(_, k)| k.position().as_dvec3()).collect();
    let fit = damage_twin::scene::similarity::umeyama(&from, &to).expect("fit");
    let (mut lo, mut hi) = (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
    for p in &to {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let extent = lo.distance(hi);
    let mut rotation: Vec<f64> = Vec::new();
    let mut position: Vec<f64> = Vec::new();
    for (p, k) in &pairs {
        let mapped = fit.apply_camera(p);
        rotation.push(f64::from(mapped.rotation.angle_between(k.rotation)).to_degrees());
        position.push(
            mapped
                .position()
                .as_dvec3()
                .distance(k.position().as_dvec3())
                / extent,
        );
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    (median(&mut rotation), median(&mut position), pairs.len())
}

fn cameras(dataset: &Dataset) -> Vec<(String, Camera)> {
    dataset
        .views
        .iter()
        .map(|v| (v.name.clone(), v.camera))
        .collect()
}

#[test]
#[ignore = "fails today: COLMAP 3.8 finds no initial pair on the 16-view synthetic orbit at \
            480x270 (docs/POSE.md, open work); run with --ignored"]
fn the_synthetic_building_is_posed_like_its_known_cameras() {
    if real_colmap().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let params = SynthParams {
        width: 480,
        height: 270,
        views: 16,
        surveys: 1,
        sparse_points: 2000,
        ..SynthParams::demo(dir.path().join("synth"))
    };
    damage_twin::synth::generate::generate(&params, &|_, _| {}).expect("synth");
    let survey = dir.path().join("synth/survey-1");
    let out = dir.path().join("posed");
    let run = binary()
        .args(["pose", "--quiet", "--threads", "2"])
        .arg(survey.join("images"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", stderr(&run));
    let known = Dataset::open(&survey, &OpenOptions::default()).unwrap();
    let posed = Dataset::open(&out, &OpenOptions::default()).unwrap();
    let (rotation_deg, position, matched) = pose_errors(&cameras(&known), &cameras(&posed));
    eprintln!(
        "synthetic building: {matched} of 16 registered, median rotation error {rotation_deg:.3}°, \
         median position error {:.3} % of the extent",
        100.0 * position
    );
    assert!(matched >= 14, "{matched} registered");
    assert!(rotation_deg < 0.5, "{rotation_deg}°");
    assert!(position < 0.01, "{position}");
    // The masks beside the photos came along, and the log and summary are in the dataset.
    assert!(out.join("masks").is_dir());
    assert!(out.join("colmap/colmap.log").is_file());
    assert!(out.join("pose.json").is_file());
    // The synthetic photos carry no EXIF: no georeference, said so.
    assert!(!out.join("georef.json").exists());
}
