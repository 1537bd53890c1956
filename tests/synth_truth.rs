//! synth's ground truth agrees with its poses: known 3D damage points, projected through the
//! COLMAP cameras read back from disk, land in the written masks; survey 2's new-damage masks are
//! non-empty exactly in the views that see new damage.

use std::path::Path;

use damage_twin::damage::DamageClass;
use damage_twin::scene::Camera;
use damage_twin::scene::colmap::read_text;
use damage_twin::synth::geometry::Ray;
use damage_twin::synth::{self, SynthParams, World};
use glam::Vec3;

fn small_params(out: &Path) -> SynthParams {
    SynthParams {
        width: 320,
        height: 180,
        views: 4,
        views_survey2: 7,
        sparse_points: 2000,
        ..SynthParams::demo(out)
    }
}

/// Cameras as written (COLMAP text), in image order.
fn read_cameras(survey_dir: &Path) -> Vec<(String, Camera)> {
    let model = read_text(&survey_dir.join("sparse/0")).expect("written model reads back");
    let cam = &model.cameras[0];
    assert_eq!(cam.model.name(), "PINHOLE");
    let (k, distortion) = cam.to_pinhole(survey_dir).expect("pinhole camera");
    assert!(distortion.is_none());
    model
        .images
        .iter()
        .map(|im| {
            let (q, t) = im.pose().expect("valid pose");
            (im.name.clone(), Camera::new(k, q, t))
        })
        .collect()
}

fn grey(path: &Path) -> image::GrayImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_luma8()
}

fn depth(path: &Path) -> image::ImageBuffer<image::Luma<u16>, Vec<u16>> {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_luma16()
}

/// The pixel that sees surface point `p`, if the first surface along the camera ray is `p`
/// itself (within 2 mm) and the point is inside the image.
fn visible(cam: &Camera, world: &World, p: Vec3) -> Option<(u32, u32)> {
    let px = cam.project(p)?;
    let k = cam.intrinsics;
    if !(px.x >= 1.0 && px.y >= 1.0 && px.x < k.width as f32 - 1.0 && px.y < k.height as f32 - 1.0)
    {
        return None;
    }
    let eye = cam.position();
    let dist = (p - eye).length();
    let hit = world
        .geometry
        .intersect(&Ray::new(eye, (p - eye) / dist), 1e4)?;
    ((hit.t - dist).abs() < 2e-3).then_some((px.x as u32, px.y as u32))
}

fn any_in_3x3(mask: &image::GrayImage, x: u32, y: u32) -> bool {
    (y - 1..=y + 1).any(|yy| (x - 1..=x + 1).any(|xx| mask.get_pixel(xx, yy)[0] == 255))
}

#[test]
fn damage_points_project_into_the_written_masks_and_new_damage_is_where_it_is_seen() {
    let dir = tempfile::tempdir().unwrap();
    let params = small_params(dir.path());
    synth::generate(&params, &|_, _| {}).expect("synth runs");
    let world = World::new(&params);

    // Poses and masks agree: every visible damage point hits its class within one pixel.
    let s1 = dir.path().join("survey-1");
    let cams = read_cameras(&s1);
    assert_eq!(cams.len(), params.views);
    let points = world.damage_points(1, 0.02, false);
    let mut checked = [0usize; 3];
    let mut missed = [0usize; 3];
    for (name, cam) in &cams {
        let masks: Vec<_> = DamageClass::ALL
            .iter()
            .map(|c| grey(&s1.join("masks").join(c.id()).join(name)))
            .collect();
        let d = depth(&s1.join("truth/depth").join(name));
        for p in &points {
            let Some((x, y)) = visible(cam, &world, p.position) else {
                continue;
            };
            // Depth is camera z in mm (not ray length, which differs by up to 15 % off-axis).
            let z = cam.world_to_camera(p.position).z;
            // Within a pixel (the point may sit beside a depth edge).
            let depth_ok = (y - 1..=y + 1).any(|yy| {
                (x - 1..=x + 1).any(|xx| {
                    let written = d.get_pixel(xx, yy)[0] as f32 / 1000.0;
                    (written - z).abs() < 0.05 + 0.02 * z
                })
            });
            assert!(
                depth_ok,
                "{name}: written depth disagrees with z {z} at ({x}, {y})"
            );
            let k = p.class.channel();
            checked[k] += 1;
            // Classes are exclusive and rebar wins: at coarse resolution exposed bars may cover
            // a spall's core, so a spall point may land on the rebar mask.
            let found = any_in_3x3(&masks[k], x, y)
                || (p.class == DamageClass::Spalling && any_in_3x3(&masks[2], x, y));
            if !found {
                missed[k] += 1;
            }
        }
    }
    eprintln!("visible damage points per class {checked:?}, missed {missed:?}");
    assert!(
        checked[0] > 200 && checked[1] > 200,
        "too few visible points: {checked:?}"
    );
    for k in 0..3 {
        // Measured: misses come only from points on spall/crack borders where the 0-footprint
        // classification and the pixel-footprint one differ; well under 1 %.
        assert!(
            missed[k] * 100 <= checked[k],
            "class {k}: {} of {} missed",
            missed[k],
            checked[k]
        );
    }

    // New damage: masks non-empty exactly where new-damage points are visible.
    let s2 = dir.path().join("survey-2");
    let cams = read_cameras(&s2);
    assert_eq!(cams.len(), params.views_survey2);
    let new_points = world.damage_points(2, 0.01, true);
    assert!(!new_points.is_empty());
    let (mut seeing, mut blind) = (0, 0);
    for (name, cam) in &cams {
        let seen = new_points
            .iter()
            .filter(|p| visible(cam, &world, p.position).is_some())
            .count();
        let pixels: usize = DamageClass::ALL
            .iter()
            .map(|c| {
                let m = grey(&s2.join("truth/new-damage").join(c.id()).join(name));
                m.pixels().filter(|p| p[0] == 255).count()
            })
            .sum();
        eprintln!("{name}: {seen} visible new-damage points, {pixels} new-damage pixels");
        assert_eq!(
            seen > 0,
            pixels > 0,
            "{name}: {seen} points visible but {pixels} mask pixels"
        );
        if seen > 0 {
            seeing += 1;
        } else {
            blind += 1;
        }
    }
    assert!(
        seeing > 0 && blind > 0,
        "the path must include views with and without new damage"
    );
}
