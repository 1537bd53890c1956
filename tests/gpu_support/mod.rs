//! Shared by the `gpu_*` tests: the device (a missing adapter FAILS: CI runs on lavapipe), small
//! random scenes with labels and SH degree 3, and image comparison helpers.
#![allow(dead_code)]

use glam::{Quat, Vec3};

use damage_twin::gpu::GpuContext;
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use damage_twin::splats::model::{SH_C0, logit};

/// The GPU context, or a test failure naming the driver package (never a skip).
pub fn context() -> GpuContext {
    match GpuContext::new() {
        Ok(ctx) => ctx,
        Err(e) => panic!("GPU tests need an adapter (CI uses lavapipe): {e}"),
    }
}

pub fn camera(width: u32, height: u32) -> Camera {
    let k = Intrinsics {
        width,
        height,
        fx: 0.9 * width as f32,
        fy: 0.9 * width as f32,
        cx: 0.5 * width as f32 + 0.3,
        cy: 0.5 * height as f32 - 0.2,
    };
    Camera::look_at(
        k,
        Vec3::new(0.3, -0.8, -5.0),
        Vec3::new(0.0, 0.1, 0.0),
        Vec3::NEG_Y,
    )
}

/// `n` Gaussians in a box around the origin (some partly off-screen), anisotropic, rotated,
/// SH degree 3 and `labels` label channels.
pub fn random_splats(n: usize, labels: usize, seed: u64) -> Splats {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut s = Splats::empty(3, labels);
    let mut sh = vec![0.0f32; 48];
    let mut lab = vec![0.0f32; labels];
    for i in 0..n {
        let mean = Vec3::new(
            rng.f32() * 4.0 - 2.0,
            rng.f32() * 3.0 - 1.5,
            rng.f32() * 4.0 - 2.0,
        );
        let base = -3.5 + 1.5 * rng.f32();
        let log_scale = Vec3::new(
            base + 0.6 * rng.f32(),
            base + 0.6 * rng.f32(),
            base + 0.6 * rng.f32(),
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
            *v = (rng.f32() - 0.5) * 0.3;
        }
        for v in lab.iter_mut() {
            *v = rng.f32() * 8.0 - 4.0;
        }
        s.push(
            mean,
            log_scale,
            rotation,
            logit(0.05 + 0.9 * rng.f32()),
            &sh,
            &lab,
            i as u64,
            0,
        );
    }
    s
}

/// Largest absolute difference and mean absolute difference.
pub fn diff_stats(a: &[f32], b: &[f32]) -> (f32, f32) {
    assert_eq!(a.len(), b.len(), "buffer lengths differ");
    let mut max = 0.0f32;
    let mut sum = 0.0f64;
    for (x, y) in a.iter().zip(b) {
        let d = (x - y).abs();
        // NaN must fail the caller's tolerance check: f32::max would drop it.
        if d.is_nan() {
            return (f32::NAN, f32::NAN);
        }
        max = max.max(d);
        sum += d as f64;
    }
    (max, (sum / a.len().max(1) as f64) as f32)
}
