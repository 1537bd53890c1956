//! The plan seen from above: the structure's points (grey), each block's kept part in
//! alternating tints, its margins as thin lines, the boundaries in red, and the cameras as dots
//! coloured by how many blocks use them (blue: one, orange: several, black: none — held out or
//! seeing nothing).

use std::path::Path;

use glam::Vec3;

use crate::blocks::plan::Plan;
use crate::scene::{Dataset, RgbImage, SceneError};

/// Width of the picture in pixels; its height follows the structure's aspect (at least 120).
const WIDTH: u32 = 900;

/// Draws `plan` over `dataset` and saves it as a PNG at `path`.
pub fn save_plan_picture(path: &Path, plan: &Plan, dataset: &Dataset) -> Result<(), SceneError> {
    let centres: Vec<Vec3> = dataset
        .views
        .iter()
        .map(|v| plan.frame.coordinates(v.camera.position()))
        .collect();
    let first = plan.blocks[0].start;
    let last = plan.blocks[plan.blocks.len() - 1].end;
    // The view covers the structure, its margins and the cameras.
    let (mut a0, mut a1) = (first - plan.margin, last + plan.margin);
    let (mut c0, mut c1) = (plan.cross_range[0], plan.cross_range[1]);
    for c in &centres {
        (a0, a1) = (a0.min(c.x), a1.max(c.x));
        (c0, c1) = (c0.min(c.y), c1.max(c.y));
    }
    let pad = 0.05 * (a1 - a0).max(c1 - c0).max(1e-3);
    let (a0, a1, c0, c1) = (a0 - pad, a1 + pad, c0 - pad, c1 + pad);
    let scale = WIDTH as f32 / (a1 - a0);
    let height = (((c1 - c0) * scale).ceil() as u32).clamp(120, 4 * WIDTH);
    let mut image = RgbImage {
        width: WIDTH,
        height,
        data: vec![1.0; (WIDTH * height * 3) as usize],
    };
    let column = |a: f32| ((a - a0) * scale).clamp(0.0, WIDTH as f32 - 1.0) as u32;
    let row = |c: f32| ((c1 - c) * scale).clamp(0.0, height as f32 - 1.0) as u32;
    let put = |image: &mut RgbImage, x: u32, y: u32, colour: [f32; 3]| {
        if x < image.width && y < image.height {
            let p = ((y * image.width + x) * 3) as usize;
            image.data[p..p + 3].copy_from_slice(&colour);
        }
    };
    let (top, bottom) = (row(plan.cross_range[1]), row(plan.cross_range[0]));
    for (k, block) in plan.blocks.iter().enumerate() {
        let tint = match (&block.skipped, k % 2) {
            (Some(_), _) => [0.85, 0.85, 0.85],
            (None, 0) => [0.86, 0.93, 1.0],
            (None, _) => [0.88, 1.0, 0.88],
        };
        let start = if k == 0 { a0 } else { block.start };
        let end = if k + 1 == plan.blocks.len() {
            a1
        } else {
            block.end
        };
        for x in column(start)..=column(end) {
            for y in top..=bottom {
                put(&mut image, x, y, tint);
            }
        }
    }
    if let Some(points) = dataset.points.as_ref() {
        let stride = points.positions.len().div_ceil(50_000).max(1);
        for &p in points.positions.iter().step_by(stride) {
            let c = plan.frame.coordinates(p);
            put(&mut image, column(c.x), row(c.y), [0.45, 0.45, 0.45]);
        }
    }
    for (k, block) in plan.blocks.iter().enumerate() {
        let mut lines = Vec::new();
        if k > 0 {
            lines.push((block.start, [0.85, 0.1, 0.1]));
            lines.push((block.start - plan.margin, [0.55, 0.55, 0.8]));
        }
        if k + 1 < plan.blocks.len() {
            lines.push((block.end + plan.margin, [0.55, 0.55, 0.8]));
        }
        for (a, colour) in lines {
            for y in top..=bottom {
                put(&mut image, column(a), y, colour);
            }
        }
    }
    for (view, c) in dataset.views.iter().zip(&centres) {
        let uses = plan
            .blocks
            .iter()
            .filter(|b| b.photos.contains(&view.name))
            .count();
        let colour = match uses {
            0 => [0.0, 0.0, 0.0],
            1 => [0.1, 0.3, 0.9],
            _ => [0.95, 0.55, 0.05],
        };
        let (x, y) = (column(c.x), row(c.y));
        for dy in 0..3 {
            for dx in 0..3 {
                put(
                    &mut image,
                    (x + dx).saturating_sub(1),
                    (y + dy).saturating_sub(1),
                    colour,
                );
            }
        }
    }
    crate::scene::load::save_png(path, &image)
}
