//! Where a render's pixels lie along the structure: each pixel's rendered surface (its depth,
//! where it is at least 5 % opaque) placed in the world and measured along the plan's long axis.
//! The seam report bands pixels by it; `twin detect` attributes changed pixels to blocks by it.

use glam::Vec3;

use crate::blocks::plan::Plan;
use crate::raster::RenderOutput;
use crate::scene::Camera;

/// Least opacity at which a pixel's depth places it on the surface.
pub const SURFACE_ALPHA: f32 = 0.05;

/// Per pixel of `out` (rendered at `camera`), the long-axis coordinate of its surface, or None
/// where the render is too transparent to have one.
pub fn surface_along(out: &RenderOutput, camera: &Camera, plan: &Plan) -> Vec<Option<f32>> {
    let k = camera.intrinsics;
    let to_world = camera.rotation.inverse();
    let mut along = vec![None; (out.width * out.height) as usize];
    for y in 0..out.height {
        for x in 0..out.width {
            let p = (y * out.width + x) as usize;
            let alpha = out.alpha[p];
            if alpha < SURFACE_ALPHA {
                continue;
            }
            let z = out.depth[p] / alpha;
            let in_camera = Vec3::new(
                (x as f32 + 0.5 - k.cx) / k.fx * z,
                (y as f32 + 0.5 - k.cy) / k.fy * z,
                z,
            );
            let world = to_world * (in_camera - camera.translation);
            along[p] = Some(plan.frame.coordinates(world).x);
        }
    }
    along
}

/// The block of `plan` whose own box holds the surface at `along` (the block that keeps it at
/// the merge).
pub fn block_of(plan: &Plan, along: f32) -> usize {
    (0..plan.blocks.len())
        .find(|&k| plan.keeps(k, along))
        .unwrap_or(plan.blocks.len() - 1)
}
