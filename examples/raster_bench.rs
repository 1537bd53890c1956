//! Times the CPU rasterizer's forward and backward on a fox_bench_ds8-sized frame (134×239,
//! camera of frame 0001) for 20k / 50k / 100k Gaussians in the ball of its `points.ply`.
//! A `.ply` argument times that model instead (e.g. a trained `fox1/model.ply`).
//! Run: `RAYON_NUM_THREADS=1 cargo run --release --example raster_bench [-- N... | MODEL.ply...]`.

use std::time::Instant;

use damage_twin::raster::{Rasterizer, RenderOutput, RenderSettings, SplatGrads, StageTimings};
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use glam::{Mat4, Quat, Vec3};

fn camera() -> Camera {
    // fox_bench_ds8/transforms.json, frame images/0001.png (OpenGL camera-to-world).
    let k = Intrinsics {
        width: 134,
        height: 239,
        fx: 172.555_33,
        fy: 172.676_85,
        cx: 68.831_15,
        cy: 119.922_5,
    };
    let c2w = Mat4::from_cols_array_2d(&[
        [0.892_643_9, 0.446_419, -0.062_425_68, 0.0],
        [0.087_996, -0.036_754_52, 0.995_442_5, 0.0],
        [0.442_09, -0.894_068_9, -0.072_091_79, 0.0],
        [3.168_359_4, -5.479_49, -0.979_166_1, 1.0],
    ]);
    Camera::from_opengl_camera_to_world(k, c2w)
}

/// `n` Gaussians uniform in the radius-2.5 ball, scales like a 3-NN init at that density,
/// random rotations, opacities and degree-3 SH (a mid-training state).
fn scene(n: usize) -> Splats {
    let mut rng = fastrand::Rng::with_seed(n as u64);
    let density = n as f32 / (4.0 / 3.0 * std::f32::consts::PI * 2.5f32.powi(3));
    let spacing = density.powf(-1.0 / 3.0) * 0.7;
    let mut s = Splats::empty(3, 0);
    while s.len() < n {
        let p = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 5.0 - Vec3::splat(2.5);
        if p.length() > 2.5 {
            continue;
        }
        let ls = Vec3::splat(spacing.ln()) + Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 0.6 - 0.3;
        let q = Quat::from_xyzw(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5, rng.f32());
        let sh: Vec<f32> = (0..48)
            .map(|i| {
                if i < 3 {
                    rng.f32()
                } else {
                    0.1 * (rng.f32() - 0.5)
                }
            })
            .collect();
        let id = s.len() as u64;
        s.push(p, ls, q, 4.0 * rng.f32() - 2.5, &sh, &[], id, 0);
    }
    s
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    // A trained model (e.g. `train fox_bench_ds8 --out fox1` then `fox1/model.ply`) is timed as
    // it is; numbers are sizes of the synthetic ball.
    let mut scenes: Vec<Splats> = Vec::new();
    for a in &args {
        if a.ends_with(".ply") {
            match damage_twin::scene::ply::read_splats(std::path::Path::new(a)) {
                Ok(s) => scenes.push(s),
                Err(e) => eprintln!("{e}"),
            }
        } else if let Ok(n) = a.parse() {
            scenes.push(scene(n));
        }
    }
    if scenes.is_empty() {
        scenes = [20_000, 50_000, 100_000].map(scene).into();
    }
    let cam = camera();
    let settings = RenderSettings::default();
    println!("threads: {}", rayon::current_num_threads());
    for splats in scenes {
        let n = splats.len();
        let mut raster = Rasterizer::new();
        let mut out = RenderOutput::default();
        let mut grads = SplatGrads::zeros(&splats);
        let v_color: Vec<f32> = (0..134 * 239 * 3)
            .map(|i| ((i % 7) as f32 - 3.0) * 1e-5)
            .collect();
        let iters = 30;
        let mut total = StageTimings::default();
        let mut fwd = 0.0;
        let mut bwd = 0.0;
        for it in 0..iters + 3 {
            let t0 = Instant::now();
            raster.forward(&splats, &cam, &settings, &mut out);
            let t1 = Instant::now();
            grads.reset(&splats);
            raster.backward(&splats, &cam, &settings, &v_color, None, None, &mut grads);
            let t2 = Instant::now();
            if it >= 3 {
                fwd += (t1 - t0).as_secs_f64();
                bwd += (t2 - t1).as_secs_f64();
                let t = raster.timings();
                total.project += t.project;
                total.sort += t.sort;
                total.raster_forward += t.raster_forward;
                total.raster_backward += t.raster_backward;
                total.project_backward += t.project_backward;
            }
        }
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3 / iters as f64;
        let visible = raster.projected().radii.iter().filter(|&&r| r > 0).count();
        println!(
            "{n:>7} Gaussians ({visible} visible, {} intersections): forward {:.2} ms \
             (project {:.2}, sort {:.2}, raster {:.2}), backward {:.2} ms (raster {:.2}, project {:.2}), \
             total {:.2} ms",
            raster.tile_bins().0.len(),
            fwd * 1e3 / iters as f64,
            ms(total.project),
            ms(total.sort),
            ms(total.raster_forward),
            bwd * 1e3 / iters as f64,
            ms(total.raster_backward),
            ms(total.project_backward),
            (fwd + bwd) * 1e3 / iters as f64,
        );
    }
}
