//! Every gradient lane of the CPU rasterizer against central finite differences of the full
//! forward pass (means incl. the SH view-direction path, log-scales, quaternions, raw
//! opacities, SH up to degree 3, raw labels, via colour, alpha, depth and label outputs), plus
//! edge cases (no Gaussians, all behind the camera, NaN parameters) and thread determinism.

use damage_twin::raster::{PixelGrads, Rasterizer, RenderOutput, RenderSettings, SplatGrads};
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use glam::{Quat, Vec3};

const W: u32 = 64;
const H: u32 = 48;
const LABELS: usize = 2;

fn camera() -> Camera {
    let k = Intrinsics {
        width: W,
        height: H,
        fx: 58.0,
        fy: 60.0,
        cx: 31.0,
        cy: 25.0,
    };
    Camera::look_at(
        k,
        Vec3::new(0.6, -0.5, -4.0),
        Vec3::new(0.05, 0.0, 0.1),
        Vec3::new(0.1, -1.0, 0.0),
    )
}

/// The 1/255 skip is a true discontinuity of the image (a pixel crossing it jumps by ~1/255);
/// with central differences of step eps it adds ~1/(255 · 2 eps) per crossing, which swamps
/// the derivative (measured: ~0.3 crossings per step at eps = 2e-4). The gradient tests turn
/// the skip off; everything else (clamps, termination, tiles) stays as rendered.
fn settings() -> RenderSettings {
    RenderSettings {
        background: Vec3::new(0.2, 0.5, 0.9),
        sh_degree: 3,
        alpha_max: 0.99,
        alpha_threshold: 0.0,
        sh_direction_grad: true,
        ..RenderSettings::default()
    }
}

/// A small random scene: Gaussians of a few pixels to a quarter of the image, opacities
/// below the alpha clamp, colours away from the clamp at 0.
fn scene(seed: u64, n: usize) -> Splats {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut u = |lo: f32, hi: f32| lo + (hi - lo) * rng.f32();
    let mut s = Splats::empty(3, LABELS);
    for g in 0..n {
        let mean = Vec3::new(u(-1.0, 1.0), u(-0.8, 0.8), u(-0.5, 0.5));
        let log_scale = Vec3::new(u(0.06, 0.3).ln(), u(0.06, 0.3).ln(), u(0.06, 0.3).ln());
        let q = Quat::from_xyzw(u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0));
        let q = q * (u(0.5, 2.0) / q.length());
        let raw_opacity = u(-1.0, 2.0);
        let mut sh = vec![0.0; 48];
        for (i, c) in sh.iter_mut().enumerate() {
            *c = if i < 3 { u(0.2, 1.2) } else { u(-0.15, 0.15) };
        }
        let labels = [u(-2.0, 2.0), u(-2.0, 2.0)];
        s.push(mean, log_scale, q, raw_opacity, &sh, &labels, g as u64, 0);
    }
    s
}

/// Fixed random per-pixel weights: the loss is `sum weights · outputs`, so they are also the
/// per-pixel gradients.
struct Weights {
    color: Vec<f32>,
    alpha: Vec<f32>,
    depth: Vec<f32>,
    labels: Vec<f32>,
}

fn weights(seed: u64) -> Weights {
    let mut rng = fastrand::Rng::with_seed(seed);
    let px = (W * H) as usize;
    let mut v = |n: usize, scale: f32| (0..n).map(|_| scale * (2.0 * rng.f32() - 1.0)).collect();
    Weights {
        color: v(px * 3, 1.0),
        alpha: v(px, 1.0),
        depth: v(px, 0.2),
        labels: v(px * LABELS, 1.0),
    }
}

fn loss(out: &RenderOutput, w: &Weights) -> f64 {
    let dot =
        |a: &[f32], b: &[f32]| -> f64 { a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum() };
    dot(&out.color, &w.color)
        + dot(&out.alpha, &w.alpha)
        + dot(&out.depth, &w.depth)
        + dot(&out.labels, &w.labels)
}

fn analytic(splats: &Splats, w: &Weights, settings: &RenderSettings) -> SplatGrads {
    let mut raster = Rasterizer::new();
    let mut out = RenderOutput::default();
    raster.forward(splats, &camera(), settings, &mut out);
    let mut grads = SplatGrads::zeros(splats);
    let v = PixelGrads {
        color: &w.color,
        alpha: Some(&w.alpha),
        depth: Some(&w.depth),
        labels: Some(&w.labels),
    };
    raster.backward_pixels(splats, &camera(), settings, &v, &mut grads);
    grads
}

/// A parameter lane: reads/writes one f32 of the splats.
#[derive(Clone, Copy, Debug)]
enum Lane {
    Mean(usize, usize),
    LogScale(usize, usize),
    Rotation(usize, usize),
    Opacity(usize),
    Sh(usize),
    Label(usize),
}

impl Lane {
    fn get(self, s: &Splats) -> f32 {
        match self {
            Lane::Mean(g, a) => s.means[g][a],
            Lane::LogScale(g, a) => s.log_scales[g][a],
            Lane::Rotation(g, a) => glam::Vec4::from(s.rotations[g])[a],
            Lane::Opacity(g) => s.raw_opacities[g],
            Lane::Sh(i) => s.sh[i],
            Lane::Label(i) => s.raw_labels[i],
        }
    }

    fn set(self, s: &mut Splats, v: f32) {
        match self {
            Lane::Mean(g, a) => s.means[g][a] = v,
            Lane::LogScale(g, a) => s.log_scales[g][a] = v,
            Lane::Rotation(g, a) => {
                let mut q = glam::Vec4::from(s.rotations[g]);
                q[a] = v;
                s.rotations[g] = Quat::from_vec4(q);
            }
            Lane::Opacity(g) => s.raw_opacities[g] = v,
            Lane::Sh(i) => s.sh[i] = v,
            Lane::Label(i) => s.raw_labels[i] = v,
        }
    }

    fn grad(self, g: &SplatGrads) -> f32 {
        match self {
            Lane::Mean(i, a) => g.v_means[i][a],
            Lane::LogScale(i, a) => g.v_log_scales[i][a],
            Lane::Rotation(i, a) => g.v_rotations[i][a],
            Lane::Opacity(i) => g.v_raw_opacities[i],
            Lane::Sh(i) => g.v_sh[i],
            Lane::Label(i) => g.v_raw_labels[i],
        }
    }

    /// Step: small enough that the alpha-threshold boundary (a true discontinuity of the
    /// renderer) rarely moves across a pixel centre, large enough for f32 rendering.
    fn eps(self) -> f32 {
        match self {
            Lane::Sh(_) | Lane::Label(_) => 1e-2,
            _ => 2e-4,
        }
    }

    fn kind(self) -> usize {
        match self {
            Lane::Mean(..) => 0,
            Lane::LogScale(..) => 1,
            Lane::Rotation(..) => 2,
            Lane::Opacity(_) => 3,
            Lane::Sh(_) => 4,
            Lane::Label(_) => 5,
        }
    }
}

const KINDS: [&str; 6] = [
    "means",
    "log_scales",
    "rotations",
    "raw_opacities",
    "sh",
    "labels",
];

struct Fd {
    central: f64,
    plus: f64,
    minus: f64,
}

fn finite_difference(splats: &Splats, lane: Lane, w: &Weights, settings: &RenderSettings) -> Fd {
    let mut raster = Rasterizer::new();
    let mut out = RenderOutput::default();
    let mut eval = |s: &Splats| {
        raster.forward(s, &camera(), settings, &mut out);
        loss(&out, w)
    };
    let x = lane.get(splats);
    let mut s = splats.clone();
    let xp = x + lane.eps();
    let xm = x - lane.eps();
    lane.set(&mut s, xp);
    let lp = eval(&s);
    lane.set(&mut s, xm);
    let lm = eval(&s);
    let l0 = eval(splats);
    Fd {
        central: (lp - lm) / (xp as f64 - xm as f64),
        plus: (lp - l0) / (xp as f64 - x as f64),
        minus: (l0 - lm) / (x as f64 - xm as f64),
    }
}

/// Central difference within 2 % (+ a floor scaled to the parameter kind's gradient size), or,
/// when the step crossed the alpha-threshold discontinuity on one side, one of the one-sided
/// differences within 4 %. A 10 % error in the analytic gradient fails both (checked below).
fn agrees(analytic: f64, fd: &Fd, floor: f64) -> (bool, bool) {
    let close =
        |v: f64, rel: f64| (v - analytic).abs() <= rel * analytic.abs().max(v.abs()) + floor;
    if close(fd.central, 0.02) {
        return (true, false);
    }
    (close(fd.plus, 0.04) || close(fd.minus, 0.04), true)
}

fn lanes(splats: &Splats) -> Vec<Lane> {
    let mut lanes = Vec::new();
    for g in 0..splats.len() {
        for a in 0..3 {
            lanes.push(Lane::Mean(g, a));
            lanes.push(Lane::LogScale(g, a));
        }
        for a in 0..4 {
            lanes.push(Lane::Rotation(g, a));
        }
        lanes.push(Lane::Opacity(g));
    }
    lanes.extend((0..splats.sh.len()).map(Lane::Sh));
    lanes.extend((0..splats.raw_labels.len()).map(Lane::Label));
    lanes
}

#[test]
fn every_gradient_lane_matches_central_finite_differences() {
    let settings = settings();
    for seed in [1u64, 2] {
        let splats = scene(seed, 8);
        let w = weights(seed + 100);
        let grads = analytic(&splats, &w, &settings);
        let all = lanes(&splats);
        // Per kind: the RMS analytic gradient sets the absolute floor (f32 noise of the loss
        // difference is ~1e-6 / (2 eps), far below it).
        let mut rms = [0.0f64; 6];
        let mut count = [0usize; 6];
        for lane in &all {
            rms[lane.kind()] += (lane.grad(&grads) as f64).powi(2);
            count[lane.kind()] += 1;
        }
        for k in 0..6 {
            rms[k] = (rms[k] / count[k].max(1) as f64).sqrt();
        }
        let mut failures = Vec::new();
        let mut one_sided = 0;
        let mut significant = 0;
        let mut caught = 0;
        let mut worst = [0.0f64; 6];
        for lane in &all {
            let a = lane.grad(&grads) as f64;
            let fd = finite_difference(&splats, *lane, &w, &settings);
            let floor = 2e-3 * rms[lane.kind()] + 1e-4;
            let (ok, fallback) = agrees(a, &fd, floor);
            if !ok {
                failures.push(format!(
                    "seed {seed} {lane:?}: analytic {a:.6e}, central {:.6e}, plus {:.6e}, minus {:.6e}, floor {floor:.1e}",
                    fd.central, fd.plus, fd.minus
                ));
            }
            one_sided += fallback as usize;
            let rel = (fd.central - a).abs() / (a.abs() + floor);
            worst[lane.kind()] = worst[lane.kind()].max(rel);
            if a.abs() > 20.0 * floor {
                significant += 1;
                caught += !agrees(1.1 * a, &fd, floor).0 as usize;
            }
        }
        for k in 0..6 {
            eprintln!(
                "seed {seed} {:>13}: rms grad {:.3e}, worst |fd - a| / (|a| + floor) {:.3e}",
                KINDS[k], rms[k], worst[k]
            );
        }
        eprintln!(
            "seed {seed}: {} lanes, {one_sided} needed a one-sided difference, \
             10% perturbation caught on {caught}/{significant} significant lanes",
            all.len()
        );
        for f in &failures {
            eprintln!("MISMATCH {f}");
        }
        assert!(failures.is_empty(), "{} lanes disagree", failures.len());
        assert!(rms.iter().all(|&r| r > 0.0), "every kind has gradients");
        assert!(one_sided * 20 <= all.len(), "too many threshold crossings");
        assert!(
            caught * 100 >= significant * 97,
            "a 10% gradient error must fail the check"
        );
    }
}

#[test]
fn detached_sh_direction_changes_only_means() {
    let splats = scene(3, 6);
    let w = weights(7);
    let full = analytic(&splats, &w, &settings());
    let detached = analytic(
        &splats,
        &w,
        &RenderSettings {
            sh_direction_grad: false,
            ..settings()
        },
    );
    assert_eq!(full.v_sh, detached.v_sh);
    assert_eq!(full.v_log_scales, detached.v_log_scales);
    assert_ne!(full.v_means, detached.v_means);
}

#[test]
fn backward_overwrites_the_previous_gradients() {
    let splats = scene(5, 40);
    let w = weights(5);
    let fresh = analytic(&splats, &w, &settings());
    // Culled Gaussians included: move a few behind the camera so no pixel uses them.
    let mut partly_culled = splats.clone();
    for m in partly_culled.means.iter_mut().step_by(5) {
        m.z -= 10.0;
    }
    let mut raster = Rasterizer::new();
    let mut out = RenderOutput::default();
    let v = PixelGrads {
        color: &w.color,
        alpha: Some(&w.alpha),
        depth: Some(&w.depth),
        labels: Some(&w.labels),
    };
    let mut grads = SplatGrads::zeros(&splats);
    raster.forward(&partly_culled, &camera(), &settings(), &mut out);
    raster.backward_pixels(&partly_culled, &camera(), &settings(), &v, &mut grads);
    // A second frame into the same, now stale, gradients.
    raster.forward(&splats, &camera(), &settings(), &mut out);
    raster.backward_pixels(&splats, &camera(), &settings(), &v, &mut grads);
    assert_eq!(grads.v_means, fresh.v_means);
    assert_eq!(grads.v_log_scales, fresh.v_log_scales);
    assert_eq!(grads.v_rotations, fresh.v_rotations);
    assert_eq!(grads.v_raw_opacities, fresh.v_raw_opacities);
    assert_eq!(grads.v_sh, fresh.v_sh);
    assert_eq!(grads.v_raw_labels, fresh.v_raw_labels);
    assert_eq!(grads.v_means2d_norm, fresh.v_means2d_norm);
    assert_eq!(grads.visible, fresh.visible);
}

#[test]
fn no_gaussians_render_the_background() {
    let splats = Splats::empty(3, LABELS);
    let mut raster = Rasterizer::new();
    let mut out = RenderOutput::default();
    raster.forward(&splats, &camera(), &settings(), &mut out);
    assert_eq!(out.color.len(), (W * H * 3) as usize);
    assert!(out.color.chunks(3).all(|c| c == [0.2, 0.5, 0.9]));
    assert!(out.alpha.iter().all(|&a| a == 0.0));
    let w = weights(1);
    let mut grads = SplatGrads::zeros(&splats);
    raster.backward(
        &splats,
        &camera(),
        &settings(),
        &w.color,
        None,
        None,
        &mut grads,
    );
    assert!(grads.v_means.is_empty());
}

#[test]
fn gaussians_behind_the_camera_are_culled_with_zero_gradients() {
    let mut splats = scene(4, 5);
    // Camera at z = -4 looking towards +z: move everything behind it.
    for m in splats.means.iter_mut() {
        m.z -= 10.0;
    }
    let mut raster = Rasterizer::new();
    let mut out = RenderOutput::default();
    raster.forward(&splats, &camera(), &settings(), &mut out);
    assert!(raster.projected().radii.iter().all(|&r| r == 0));
    assert!(out.alpha.iter().all(|&a| a == 0.0));
    let w = weights(2);
    let mut grads = SplatGrads::zeros(&splats);
    raster.backward(
        &splats,
        &camera(),
        &settings(),
        &w.color,
        Some(&w.alpha),
        None,
        &mut grads,
    );
    assert!(grads.visible.iter().all(|&v| !v));
    assert!(grads.v_means.iter().all(|&v| v == Vec3::ZERO));
    assert!(grads.v_sh.iter().all(|&v| v == 0.0));
}

#[test]
fn nan_parameters_are_culled_not_propagated() {
    let mut splats = scene(5, 6);
    let mut raster = Rasterizer::new();
    let mut out = RenderOutput::default();
    raster.forward(&splats, &camera(), &settings(), &mut out);
    assert!(
        raster.projected().radii.iter().all(|&r| r > 0),
        "all six visible before the NaNs"
    );
    splats.means[0].x = f32::NAN;
    splats.log_scales[1].y = f32::NAN;
    splats.rotations[2] = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);
    splats.raw_opacities[3] = f32::NAN;
    splats.sh[4 * 48 + 5] = f32::INFINITY;
    splats.raw_labels[5 * LABELS] = f32::NAN;
    raster.forward(&splats, &camera(), &settings(), &mut out);
    assert!(
        raster.projected().radii.iter().all(|&r| r == 0),
        "all six culled"
    );
    // A negative infinity in the SH is culled too, although the colour clamp `max(sum + 0.5, 0)`
    // turns it into a finite 0 (the GPU projection culls it as well).
    let mut minus_inf = scene(5, 6);
    minus_inf.sh[2 * 48] = f32::NEG_INFINITY;
    raster.forward(&minus_inf, &camera(), &settings(), &mut out);
    let radii = &raster.projected().radii;
    assert_eq!(radii[2], 0, "a -inf SH coefficient was not culled");
    assert!(radii.iter().enumerate().all(|(g, &r)| g == 2 || r > 0));
    raster.forward(&splats, &camera(), &settings(), &mut out);
    assert!(
        out.color
            .iter()
            .chain(&out.alpha)
            .chain(&out.labels)
            .all(|v| v.is_finite())
    );
    let w = weights(3);
    let mut grads = SplatGrads::zeros(&splats);
    raster.backward(
        &splats,
        &camera(),
        &settings(),
        &w.color,
        Some(&w.alpha),
        Some(&w.labels),
        &mut grads,
    );
    assert!(grads.v_means.iter().all(|v| *v == Vec3::ZERO));
    assert!(
        grads
            .v_sh
            .iter()
            .chain(&grads.v_raw_labels)
            .all(|&v| v == 0.0)
    );
}

#[test]
fn results_are_identical_for_one_and_two_threads() {
    let splats = scene(6, 40);
    let w = weights(4);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        pool.install(|| {
            let mut raster = Rasterizer::new();
            let mut out = RenderOutput::default();
            raster.forward(&splats, &camera(), &settings(), &mut out);
            let grads = analytic(&splats, &w, &settings());
            (out.color, grads.v_means, grads.v_sh)
        })
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn simd_build_follows_the_environment() {
    damage_twin::simd::assert_level_follows_the_environment();
}

/// The same checks with the kernels machines without AVX-512 or AVX2 run.
#[test]
fn gradient_checks_pass_on_the_lower_simd_builds() {
    damage_twin::simd::rerun_tests_on_lower_builds(&[
        "simd_build_follows_the_environment",
        "every_gradient_lane_matches_central_finite_differences",
        "nan_parameters_are_culled_not_propagated",
        "results_are_identical_for_one_and_two_threads",
    ]);
}
