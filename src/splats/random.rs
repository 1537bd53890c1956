//! Random Gaussians spread through a camera's view: a model of any size for timing renderers
//! (`bench-render --random N`) without a trained one.

use glam::{Quat, Vec3};

use crate::scene::Camera;
use crate::splats::Splats;
use crate::splats::model::{SH_C0, logit};

/// `n` random Gaussians inside the camera's view between depths 2 and 12, a few pixels to a few
/// dozen across, SH degree 3 with a random DC colour and small higher-order terms.
pub fn random_in_view(n: usize, camera: &Camera, seed: u64) -> Splats {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut s = Splats::empty(3, 0);
    let k = camera.intrinsics;
    let cam_to_world = camera.rotation.inverse();
    let centre = camera.position();
    let mut sh = vec![0.0f32; 48];
    for i in 0..n {
        let z = 2.0 + 10.0 * rng.f32();
        let px = rng.f32() * k.width as f32;
        let py = rng.f32() * k.height as f32;
        let p_cam = Vec3::new((px - k.cx) / k.fx * z, (py - k.cy) / k.fy * z, z);
        let mean = centre + cam_to_world * p_cam;
        // Pixel footprint 1..20 px at this depth.
        let size_px = 1.0 + 19.0 * rng.f32() * rng.f32();
        let sigma = size_px * z / k.fx / 3.0;
        let log_scale = Vec3::new(
            (sigma * (0.5 + rng.f32())).ln(),
            (sigma * (0.5 + rng.f32())).ln(),
            (sigma * (0.5 + rng.f32())).ln(),
        );
        let rotation = Quat::from_xyzw(
            rng.f32() - 0.5,
            rng.f32() - 0.5,
            rng.f32() - 0.5,
            rng.f32() - 0.5,
        );
        for v in sh.iter_mut().take(3) {
            *v = (rng.f32() - 0.5) / SH_C0;
        }
        for v in sh.iter_mut().skip(3) {
            *v = (rng.f32() - 0.5) * 0.2;
        }
        s.push(
            mean,
            log_scale,
            rotation,
            logit(0.2 + 0.7 * rng.f32()),
            &sh,
            &[],
            i as u64,
            0,
        );
    }
    s
}
