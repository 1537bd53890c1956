//! Which pixels of a photo belong to a block: not those where the structure's sparse points show
//! something outside the block's enlarged box in front. Without it a block asked to explain the
//! rest of a long structure seen past its end (a view along the structure) puts fog in front of
//! the camera, inside its box, which the merge keeps. Per cell of the image, the nearest point
//! seen there says whose the cell is; cells no point falls in (sky) stay the block's.

use crate::blocks::plan::Plan;
use crate::scene::{Camera, Mask};

/// Cells per image width (a 240-pixel photo gets 8-pixel cells, a 5,000-pixel one 167).
const CELLS_ACROSS: u32 = 30;

/// The pixels of a `camera`'s image that block `k` of `plan` may train on, given the
/// structure's `points` and, per point, whether it lies in the block's enlarged box.
pub fn block_pixels(camera: &Camera, points: &[glam::Vec3], inside: &[bool]) -> Mask {
    let k = camera.intrinsics;
    let cell = (k.width / CELLS_ACROSS).max(1);
    let (cols, rows) = (k.width.div_ceil(cell), k.height.div_ceil(cell));
    // Per cell: depth of the nearest point and whether it is the block's.
    let mut nearest = vec![(f32::INFINITY, true); (cols * rows) as usize];
    for (p, &own) in points.iter().zip(inside) {
        let Some((x, y)) = camera.pixel_of(*p) else {
            continue;
        };
        let depth = camera.world_to_camera(*p).z;
        let c = ((y / cell) * cols + x / cell) as usize;
        if depth < nearest[c].0 {
            nearest[c] = (depth, own);
        }
    }
    let mut mask = Mask::empty(k.width, k.height);
    for y in 0..k.height {
        for x in 0..k.width {
            let c = ((y / cell) * cols + x / cell) as usize;
            mask.data[(y * k.width + x) as usize] = u8::from(nearest[c].1);
        }
    }
    mask
}

/// Per point of `points`, whether it lies in block `k`'s enlarged box.
pub fn inside_block(plan: &Plan, k: usize, points: &[glam::Vec3]) -> Vec<bool> {
    points
        .iter()
        .map(|&p| plan.trains_on(k, plan.frame.coordinates(p).x))
        .collect()
}
