//! Checks shared by the synth tests: cameras read back from a written survey, and the agreement
//! of known 3D damage points with the written masks, depth and new-damage masks; every file of
//! an output folder, for determinism.
// Each test uses some of these.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use damage_twin::damage::DamageClass;
use damage_twin::scene::Camera;
use damage_twin::scene::colmap::read_text;
use damage_twin::synth::World;
use damage_twin::synth::damage::DamagePoint;
use damage_twin::synth::geometry::Ray;
use glam::Vec3;

/// Cameras as written (COLMAP text), in image order.
pub fn read_cameras(survey_dir: &Path) -> Vec<(String, Camera)> {
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

pub fn grey(path: &Path) -> image::GrayImage {
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
pub fn visible(cam: &Camera, world: &World, p: Vec3) -> Option<(u32, u32)> {
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

/// Projects every damage point into every camera that sees it and checks the written depth
/// (asserted) and masks: returns per class how many were checked and how many missed their mask.
pub fn damage_points_in_masks(
    survey_dir: &Path,
    world: &World,
    points: &[DamagePoint],
) -> ([usize; 3], [usize; 3]) {
    let mut checked = [0usize; 3];
    let mut missed = [0usize; 3];
    for (name, cam) in &read_cameras(survey_dir) {
        let masks: Vec<_> = DamageClass::ALL
            .iter()
            .map(|c| grey(&survey_dir.join("masks").join(c.id()).join(name)))
            .collect();
        let d = depth(&survey_dir.join("truth/depth").join(name));
        for p in points {
            let Some((x, y)) = visible(cam, world, p.position) else {
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
    (checked, missed)
}

/// Checks that survey 2's new-damage masks are non-empty exactly in the views that see a new
/// damage point; returns how many views see new damage and how many see none.
pub fn new_damage_masks_where_seen(
    survey_dir: &Path,
    world: &World,
    new_points: &[DamagePoint],
) -> (usize, usize) {
    let (mut seeing, mut blind) = (0, 0);
    for (name, cam) in &read_cameras(survey_dir) {
        let seen = new_points
            .iter()
            .filter(|p| visible(cam, world, p.position).is_some())
            .count();
        let pixels: usize = DamageClass::ALL
            .iter()
            .map(|c| {
                let m = grey(&survey_dir.join("truth/new-damage").join(c.id()).join(name));
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
    (seeing, blind)
}

/// Every file under `root`, relative path to bytes.
pub fn files(root: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let rel = path.strip_prefix(root).unwrap().to_path_buf();
                out.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    out
}
