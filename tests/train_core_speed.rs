//! Timings of train-core's per-step building blocks (ignored: run on demand with
//! `cargo test --release --test train_core_speed -- --ignored --nocapture`).

use std::time::Instant;

use damage_twin::splats::Splats;
use damage_twin::splats::init::{InitOptions, from_points, random_points};
use damage_twin::train::adam::{Adam, GroupFlags, LearningRates, ParamGrads};
use damage_twin::train::loss::{LossWorkspace, SSIM_LAMBDA, photometric_loss};
use glam::{Vec3, Vec4};

fn image(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = fastrand::Rng::with_seed(seed);
    (0..n).map(|_| rng.f32()).collect()
}

/// Process CPU seconds (user + system) from /proc/self/stat: on a shared, overloaded machine
/// wall time mostly measures the other processes, CPU time measures this code.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<f64> = after
        .split_whitespace()
        .filter_map(|v| v.parse().ok())
        .collect();
    // Fields 14 and 15 (utime, stime): the 11th and 12th numbers after the state letter.
    f.get(10)
        .zip(f.get(11))
        .map_or(f64::NAN, |(u, s)| (u + s) / 100.0)
}

/// (wall ms, CPU ms) per call.
fn time_per_call(reps: usize, mut f: impl FnMut()) -> (f64, f64) {
    f(); // warm-up: sizes the workspaces
    let (t, c) = (Instant::now(), cpu_seconds());
    for _ in 0..reps {
        f();
    }
    let wall = t.elapsed().as_secs_f64() * 1e3 / reps as f64;
    (wall, (cpu_seconds() - c) * 1e3 / reps as f64)
}

#[test]
#[ignore]
fn loss_and_backward_time() {
    for (w, h) in [(134u32, 239u32), (200, 200)] {
        let n = (w * h * 3) as usize;
        let (x, t) = (image(n, 1), image(n, 2));
        let mut ws = LossWorkspace::new();
        let mut grad = vec![0.0; n];
        let ms = time_per_call(200, || {
            photometric_loss(&mut ws, &x, &t, w, h, None, SSIM_LAMBDA, &mut grad);
        });
        let region: Vec<f32> = (0..(w * h) as usize)
            .map(|p| (p % 3 != 0) as u8 as f32)
            .collect();
        let ms_region = time_per_call(200, || {
            photometric_loss(&mut ws, &x, &t, w, h, Some(&region), SSIM_LAMBDA, &mut grad);
        });
        println!(
            "loss+backward {w}x{h}: {ms:.3?} (wall, cpu) ms/call, with region {ms_region:.3?} ({} threads)",
            rayon::current_num_threads()
        );
    }
}

#[test]
#[ignore]
fn adam_time_per_100k_gaussians() {
    let cloud = random_points(100_000, 1.3, 3);
    let t = Instant::now();
    let init = from_points(
        &cloud.0,
        &cloud.1,
        &InitOptions {
            label_channels: 3,
            ..InitOptions::default()
        },
    )
    .unwrap();
    println!(
        "init from 100k points (3-NN): {:.1} ms",
        t.elapsed().as_secs_f64() * 1e3
    );
    for degree in [0u32, 3] {
        let mut s: Splats = init.clone();
        s.set_sh_degree(degree);
        let n = s.len();
        let v3 = vec![Vec3::splat(1e-3); n];
        let v4 = vec![Vec4::splat(1e-3); n];
        let op = vec![1e-3; n];
        let sh = vec![1e-3; s.sh.len()];
        let lb = vec![1e-3; s.raw_labels.len()];
        let grads = ParamGrads {
            v_means: &v3,
            v_log_scales: &v3,
            v_rotations: &v4,
            v_raw_opacities: &op,
            v_sh: &sh,
            v_raw_labels: &lb,
        };
        let lrs = LearningRates::default().for_step(100, 4.0);
        let mut adam = Adam::new(&s);
        let ms = time_per_call(50, || {
            let found = adam.step(&mut s, &grads, &lrs, &GroupFlags::ALL_ON, None);
            assert_eq!(found, None);
        });
        println!(
            "adam step 100k Gaussians, SH degree {degree}, 3 labels: {ms:.3?} (wall, cpu) ms/call ({} threads)",
            rayon::current_num_threads()
        );
    }
}
