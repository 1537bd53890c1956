//! `damage-twin stamp` (docs/STAMP.md): same seed, same bytes; truth masks agree with the
//! stamped pixels; a decal seen from two photos lands on the same 3D spot (its corner marks
//! within 2 px of their projection through each photo's own lens, SIMPLE_RADIAL included); bad
//! input is refused in one line. On a small posed capture made here (two walls, SIMPLE_RADIAL
//! k = 0.05, four photos) and, when `../shared/data` is there, on opensfm_lund.

mod shared_data;
mod stamp_support;

use std::path::{Path, PathBuf};

use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::undistort::distort;
use damage_twin::scene::{Camera, DamageClass, Dataset, Mask, RgbImage};
use damage_twin::synth::stamp::decal::{ColourStats, Decal, Texel};
use damage_twin::synth::stamp::place::{Photo, orient_and_count, sees};
use damage_twin::synth::stamp::planes::{PlaneSearch, fit_planes};
use damage_twin::synth::stamp::render::{Lens, stamp_view};
use damage_twin::synth::stamp::{StampParams, parse_classes, stamp};
use glam::{DVec3, Vec3};
use stamp_support::{K1, fixture, params, tree, write_capture};

#[test]
fn the_same_seed_gives_the_same_bytes_and_another_seed_other_damage() {
    let f = fixture();
    let quiet = |_: usize, _: usize| {};
    let a = stamp(&params(&f, "a", 3), &quiet).unwrap();
    stamp(&params(&f, "b", 3), &quiet).unwrap();
    stamp(&params(&f, "c", 4), &quiet).unwrap();
    assert_eq!(a.decals, vec![5, 8], "survey 2 adds 2 cracks and a spall");
    let (ta, tb, tc) = (
        tree(&f.root.join("a")),
        tree(&f.root.join("b")),
        tree(&f.root.join("c")),
    );
    assert!(ta.len() > 40, "{} files", ta.len());
    // The manifests name their own output folder through the capture path only, so equal.
    assert!(ta == tb, "two runs with seed 3 differ");
    let images = |t: &[(PathBuf, Vec<u8>)]| -> Vec<Vec<u8>> {
        t.iter()
            .filter(|(p, _)| p.starts_with("survey-1/images"))
            .map(|(_, b)| b.clone())
            .collect()
    };
    assert_ne!(
        images(&ta),
        images(&tc),
        "seed 4 stamped the same photos as seed 3"
    );
    // The output opens as a dataset with its masks.
    let survey = Dataset::open(&f.root.join("a/survey-2"), &OpenOptions::default()).unwrap();
    assert_eq!(survey.views.len(), 4);
    assert_eq!(survey.mask_counts.get(&DamageClass::Crack), Some(&4));
    assert!(survey.views.iter().all(|v| {
        v.distortion
            .is_some_and(|d| (d.k1 as f64 - K1).abs() < 1e-6)
    }));
}

fn read_rgb(path: &Path) -> image::RgbImage {
    image::open(path).unwrap().to_rgb8()
}

fn read_mask(path: &Path) -> Vec<bool> {
    image::open(path)
        .unwrap()
        .to_luma8()
        .pixels()
        .map(|p| p[0] > 127)
        .collect()
}

#[test]
fn truth_masks_are_exactly_the_changed_pixels() {
    let f = fixture();
    stamp(&params(&f, "out", 9), &|_, _| {}).unwrap();
    for survey in [1, 2] {
        let root = f.root.join(format!("out/survey-{survey}"));
        let manifest: serde_json::Value =
            serde_json::from_slice(&std::fs::read(root.join("truth/manifest.json")).unwrap())
                .unwrap();
        let gain: Vec<f32> = manifest["light_gain"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .collect();
        let (mut truth_pixels, mut truth_changed) = (0usize, 0usize);
        for i in 0..4 {
            let name = format!("{i:02}.png");
            let original = read_rgb(&f.capture.join("images").join(&name));
            let stamped = read_rgb(&root.join("images").join(format!("{i:02}.png")));
            let truth: Vec<bool> = {
                let masks: Vec<Vec<bool>> = ["crack", "spalling", "rebar"]
                    .iter()
                    .map(|c| {
                        read_mask(&root.join("truth/masks").join(c).join(format!("{i:02}.png")))
                    })
                    .collect();
                (0..masks[0].len())
                    .map(|p| masks.iter().any(|m| m[p]))
                    .collect()
            };
            for (p, (a, b)) in original.pixels().zip(stamped.pixels()).enumerate() {
                // The photo under this survey's light, as 8 bits.
                let lit: Vec<i32> = (0..3)
                    .map(|c| ((a[c] as f32 / 255.0 * gain[c]).clamp(0.0, 1.0) * 255.0 + 0.5) as i32)
                    .collect();
                let changed = (0..3).any(|c| (lit[c] - b[c] as i32).abs() > 1);
                assert!(
                    !changed || truth[p],
                    "survey {survey}, {name}: pixel {p} changed outside the truth masks"
                );
                if truth[p] {
                    truth_pixels += 1;
                    truth_changed += usize::from(changed);
                }
            }
        }
        assert!(
            truth_pixels > 500,
            "survey {survey}: {truth_pixels} truth pixels"
        );
        let share = truth_changed as f64 / truth_pixels as f64;
        assert!(
            share > 0.9,
            "survey {survey}: {share:.3} of the truth pixels changed"
        );
    }
}

/// A decal of 60 × 60 texels with four 10 × 10-texel marks near its corners; the marks' 3D centres.
fn marker_decal(
    plane: usize,
    centre: DVec3,
    u: DVec3,
    v: DVec3,
    texel: f64,
) -> (Decal, Vec<DVec3>) {
    let side = 60usize;
    let origin = centre - (u + v) * (side as f64 * texel * 0.5);
    let mut texels = vec![None; side * side];
    let mut centres = Vec::new();
    // 10 × 10-texel marks, 4 texels in from the corners.
    let far = side - 14;
    for (ci, cj) in [(4usize, 4usize), (far, 4), (far, far), (4, far)] {
        for j in cj..cj + 10 {
            for i in ci..ci + 10 {
                texels[j * side + i] = Some(Texel {
                    class: DamageClass::Crack,
                    appears: 1,
                    source: [0.0; 3],
                    shade: 1.0,
                });
            }
        }
        centres.push(origin + u * ((ci as f64 + 5.0) * texel) + v * ((cj as f64 + 5.0) * texel));
    }
    let decal = Decal {
        id: 0,
        plane,
        origin,
        axis_u: u,
        axis_v: v,
        texel,
        width: side,
        height: side,
        texels,
        colours: vec![[1.0, 0.0, 0.0]; side * side],
        source_stats: ColourStats {
            mean: [0.5; 3],
            std: [0.1; 3],
        },
        facade_stats: None,
        first_survey: 1,
        source: None,
    };
    (decal, centres)
}

/// The projection of `p` through the camera and its SIMPLE_RADIAL lens, written out here.
fn project(camera: &Camera, k1: f64, p: DVec3) -> (f64, f64) {
    let q = camera.world_to_camera(p.as_vec3()).as_dvec3();
    let (u, v) = distort(q.x / q.z, q.y / q.z, k1, 0.0, 0.0, 0.0);
    let k = &camera.intrinsics;
    (k.fx as f64 * u + k.cx as f64, k.fy as f64 * v + k.cy as f64)
}

/// Centroids (pixel centres at +0.5) of the mask's 4-connected blobs of at least 3 pixels.
fn blob_centroids(mask: &Mask) -> Vec<(f64, f64)> {
    let (w, h) = (mask.width as usize, mask.height as usize);
    let mut seen = vec![false; w * h];
    let mut out = Vec::new();
    for s in 0..w * h {
        if seen[s] || mask.data[s] == 0 {
            continue;
        }
        let (mut stack, mut sum, mut n) = (vec![s], (0.0, 0.0), 0.0);
        seen[s] = true;
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            sum = (sum.0 + x as f64 + 0.5, sum.1 + y as f64 + 0.5);
            n += 1.0;
            let mut near = vec![];
            if x > 0 {
                near.push(i - 1)
            }
            if x + 1 < w {
                near.push(i + 1)
            }
            if y > 0 {
                near.push(i - w)
            }
            if y + 1 < h {
                near.push(i + w)
            }
            for j in near {
                if !seen[j] && mask.data[j] != 0 {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        if n >= 3.0 {
            out.push((sum.0 / n, sum.1 / n));
        }
    }
    out
}

/// Stamps a marker decal on the first spot of the capture's planes that two photos see well and
/// checks, in each of those photos, each mark's blob against the mark's projection: the largest error in pixels.
fn marker_error(capture: &Path, metres_per_unit: f64, texel_m: f64) -> (f64, usize) {
    let dataset = Dataset::open(capture, &OpenOptions::default()).unwrap();
    let photos: Vec<Photo> = dataset
        .views
        .iter()
        .map(|v| Photo {
            lens: Lens {
                camera: v.camera,
                distortion: v.distortion,
            },
            path: v.image_path.clone(),
        })
        .collect();
    let up = photos
        .iter()
        .map(|p| p.lens.camera.rotation.as_dquat().inverse() * DVec3::NEG_Y)
        .sum::<DVec3>()
        .normalize();
    let search = PlaneSearch {
        tolerance: 0.1 / metres_per_unit,
        cell: 0.5 / metres_per_unit,
        min_inliers: 30,
        max_planes: 4,
        iterations: 400,
    };
    let mut planes = fit_planes(&dataset.points.as_ref().unwrap().positions, up, &search, 1);
    orient_and_count(&mut planes, &photos);
    // The first spot (every 3rd inlier of each plane) that two photos see large enough.
    for plane in &planes {
        for seed in plane.inliers.iter().step_by(3) {
            let (a, b) = plane.coords(*seed);
            // The decal is drawn on its plane alone: this checks where it lands, not what
            // hides it.
            let alone = std::slice::from_ref(plane);
            let (decal, marks) = marker_decal(
                0,
                plane.point(a, b),
                plane.u,
                plane.v,
                texel_m / metres_per_unit,
            );
            let usable: Vec<&Photo> = photos
                .iter()
                .filter(|photo| marks_measurable(&photo.lens, &decal, &marks, alone))
                .collect();
            if usable.len() < 2 {
                continue;
            }
            let mut worst = 0.0f64;
            for photo in &usable {
                let (w, h) = photo.lens.size();
                let blank = RgbImage::filled(w, h, [0.5; 3]);
                let decals = std::slice::from_ref(&decal);
                let stamped = stamp_view(&blank, &photo.lens, decals, alone, 1, [1.0; 3]);
                let blobs = blob_centroids(&stamped.masks[0].1);
                assert_eq!(
                    blobs.len(),
                    4,
                    "{}: {} blobs",
                    photo.path.display(),
                    blobs.len()
                );
                let k1 = photo.lens.distortion.map_or(0.0, |d| d.k1 as f64);
                for m in &marks {
                    let (x, y) = projected_centroid(&photo.lens.camera, k1, *m, &decal);
                    let error = blobs
                        .iter()
                        .map(|b| (b.0 - x).hypot(b.1 - y))
                        .fold(f64::INFINITY, f64::min);
                    worst = worst.max(error);
                }
            }
            return (worst, usable.len());
        }
    }
    (0.0, 0)
}

/// Where the blob of the mark centred on `m` should have its centroid: the area centroid of
/// the mark's four corners as projected (under perspective the projected centre is not the
/// centroid: 3 px apart for 80 cm marks at a grazing angle on lund).
fn projected_centroid(camera: &Camera, k1: f64, m: DVec3, decal: &Decal) -> (f64, f64) {
    let half = 5.0 * decal.texel;
    let q: Vec<(f64, f64)> = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
        .iter()
        .map(|(a, b)| {
            project(
                camera,
                k1,
                m + decal.axis_u * (a * half) + decal.axis_v * (b * half),
            )
        })
        .collect();
    // Shoelace centroid of the quadrilateral.
    let (mut area, mut cx, mut cy) = (0.0, 0.0, 0.0);
    for i in 0..4 {
        let (p0, p1) = (q[i], q[(i + 1) % 4]);
        let cross = p0.0 * p1.1 - p1.0 * p0.1;
        area += cross;
        cx += (p0.0 + p1.0) * cross;
        cy += (p0.1 + p1.1) * cross;
    }
    (cx / (3.0 * area), cy / (3.0 * area))
}

/// Whether a photo sees all four marks, each side of their square spanning 30 px (marks of
/// 6 px): photos far along a street, or at a grazing angle, see them too small to centre.
fn marks_measurable(
    lens: &Lens,
    decal: &Decal,
    marks: &[DVec3],
    planes: &[damage_twin::synth::stamp::planes::Plane],
) -> bool {
    if !marks.iter().all(|m| sees(lens, *m, 0, planes)) {
        return false;
    }
    let k1 = lens.distortion.map_or(0.0, |d| d.k1 as f64);
    // Whole marks only: one cut by the image border has its blob's centroid moved.
    let (w, h) = lens.size();
    let inside = |p: DVec3| {
        let (x, y) = project(&lens.camera, k1, p);
        x >= 1.0 && y >= 1.0 && x < w as f64 - 1.0 && y < h as f64 - 1.0
    };
    let half = 5.0 * decal.texel;
    let whole = marks.iter().all(|m| {
        [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .all(|(a, b)| inside(*m + decal.axis_u * (a * half) + decal.axis_v * (b * half)))
    });
    if !whole {
        return false;
    }
    let corners: Vec<(f64, f64)> = marks
        .iter()
        .map(|m| project(&lens.camera, k1, *m))
        .collect();
    (0..4).all(|i| {
        let (a, b) = (corners[i], corners[(i + 1) % 4]);
        (a.0 - b.0).hypot(a.1 - b.1) >= 30.0
    })
}

#[test]
fn a_decal_lands_on_the_same_spot_in_every_photo() {
    let f = fixture();
    let (error, views) = marker_error(&f.capture, 1.0, 0.03);
    eprintln!("made-up capture: {views} photos, largest mark error {error:.3} px");
    assert!(views >= 2, "{views} photos see the marks");
    assert!(error <= 2.0, "{error} px");
}

#[test]
fn a_decal_lands_on_the_same_spot_in_lund_photos() {
    let Some(lund) = shared_data::path("opensfm_lund") else {
        return;
    };
    // Lund's metres per unit from its photos' EXIF GPS (docs/STAMP.md).
    let (error, views) = marker_error(&lund, 15.35, 0.08);
    eprintln!("lund: {views} photos, largest mark error {error:.3} px");
    assert!(views >= 2, "{views} photos see the marks");
    assert!(error <= 2.0, "{error} px");
}

fn one_line_error(p: &StampParams) -> String {
    let message = stamp(p, &|_, _| {}).unwrap_err().to_string();
    assert!(!message.contains('\n'), "{message}");
    message
}

#[test]
fn bad_input_is_refused_in_one_line() {
    let f = fixture();
    // No sparse points.
    let bare = f.root.join("bare");
    write_capture(&bare, &[]);
    let p = StampParams {
        capture: bare.clone(),
        ..params(&f, "x", 1)
    };
    let message = one_line_error(&p);
    assert!(message.contains("0 sparse points"), "{message}");
    // Points with no plane among them: scattered through a 10 m cube.
    let scattered = f.root.join("scattered");
    let mut rng = fastrand::Rng::with_seed(2);
    let points: Vec<Vec3> = (0..300)
        .map(|_| {
            Vec3::new(
                rng.f32() * 10.0 - 5.0,
                rng.f32() * 10.0 - 5.0,
                rng.f32() * 10.0 - 5.0,
            )
        })
        .collect();
    write_capture(&scattered, &points);
    let p = StampParams {
        capture: scattered,
        ..params(&f, "x", 1)
    };
    let message = one_line_error(&p);
    assert!(message.contains("no surface to stamp"), "{message}");
    // Rebar without spalling; a crack-photo folder without pairs.
    let p = StampParams {
        classes: vec![DamageClass::Rebar],
        ..params(&f, "x", 1)
    };
    assert!(one_line_error(&p).contains("add spalling"));
    let p = StampParams {
        crack_sources: vec![bare.join("images")],
        ..params(&f, "x", 1)
    };
    assert!(one_line_error(&p).contains("no crack photos with masks"));
    // An unknown class, in the library and on the command line.
    assert!(
        parse_classes("crack,spall")
            .unwrap_err()
            .contains("\"spall\"")
    );
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_damage-twin"))
        .args(["stamp", "--out"])
        .arg(f.root.join("y"))
        .arg("--crack-photos")
        .arg(&f.cracks)
        .args(["--classes", "crack,spall"])
        .arg(&f.capture)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("unknown damage class \"spall\""),
        "{stderr}"
    );
}
