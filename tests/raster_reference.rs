//! The plain reference rasterizer (`damage_twin::raster::reference`) against gsplat's own
//! tensors, against central finite differences of itself, and the fast `Rasterizer` (forward and
//! backward, every output and every gradient) against the reference: on gsplat's two scenes
//! (with label channels added) and on a seeded random scene with Gaussians behind the near
//! plane, off screen, in the Jacobian's clamp, huge and tiny, at an image size that is not a
//! multiple of 16, with the default alpha threshold and with none.
//!
//! Tolerances: each was set from the largest error measured on this machine (written beside
//! it; `cargo test --test raster_reference -- --nocapture` prints them) with a margin.

mod gsplat_support;

use damage_twin::raster::reference;
use damage_twin::raster::{
    PixelGrads, Projected, Rasterizer, RenderOutput, RenderSettings, SplatGrads,
};
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use damage_twin::splats::model::{SH_C0, logit};
use glam::{Quat, Vec3};
use gsplat_support::{Case, assert_close, flat_quats_wxyz, flat2, flat3};

const LABELS: usize = 3;

/// Per-pixel gradients of a loss (random weights: the loss is their dot product with the
/// outputs, so they are its gradients too).
struct Weights {
    color: Vec<f32>,
    alpha: Vec<f32>,
    depth: Vec<f32>,
    labels: Vec<f32>,
}

impl Weights {
    fn random(pixels: usize, labels: usize, seed: u64) -> Weights {
        let mut rng = fastrand::Rng::with_seed(seed);
        let mut v =
            |n: usize, scale: f32| (0..n).map(|_| scale * (2.0 * rng.f32() - 1.0)).collect();
        Weights {
            color: v(pixels * 3, 1.0),
            alpha: v(pixels, 1.0),
            depth: v(pixels, 0.2),
            labels: v(pixels * labels, 1.0),
        }
    }

    fn pixel_grads(&self) -> PixelGrads<'_> {
        PixelGrads {
            color: &self.color,
            alpha: Some(&self.alpha),
            depth: Some(&self.depth),
            labels: Some(&self.labels),
        }
    }

    fn loss(&self, out: &RenderOutput) -> f64 {
        let dot = |a: &[f32], b: &[f32]| -> f64 {
            a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum()
        };
        dot(&out.color, &self.color)
            + dot(&out.alpha, &self.alpha)
            + dot(&out.depth, &self.depth)
            + dot(&out.labels, &self.labels)
    }
}

// ---------------------------------------------------------------------------------------------
// The reference against gsplat.
// ---------------------------------------------------------------------------------------------

fn reference_matches_gsplat(name: &str) {
    let case = Case::load(name);
    let splats = case.splats();
    let (camera, settings) = (gsplat_support::camera(), gsplat_support::settings());
    let (out, projected) = reference::render(&splats, &camera, &settings);
    assert!(projected.radii.iter().all(|&r| r > 0), "all visible");
    let rgba: Vec<f32> = (0..out.alpha.len())
        .flat_map(|p| {
            let c = &out.color[p * 3..p * 3 + 3];
            [c[0], c[1], c[2], out.alpha[p]]
        })
        .collect();
    // `|a - b| <= atol + rtol |b|` per value, from the largest errors of either case: out_img
    // 8.3e-7 absolute (basic; brush accepts 1e-5 + 1e-2 |b|), xys 7.6e-6 absolute on values up
    // to about 120 px (4.4e-7 relative: f32 rounding of the division by z), conics 4.5e-8
    // absolute and 2.0e-6 relative, depths bit-identical.
    let forward: [(&str, Vec<f32>, f32, f32); 4] = [
        ("out_img", rgba, 5e-6, 1e-4),
        ("xys", flat2(&projected.means2d), 1e-5, 1e-5),
        ("conics", flat3(&projected.conics), 1e-6, 2e-5),
        ("depths", projected.depths.clone(), 1e-6, 0.0),
    ];
    for (key, got, atol, rtol) in &forward {
        assert_close(&format!("{name} {key}"), got, case.get(key), *atol, *rtol);
    }

    let (v_color, v_alpha) = case.pixel_grads();
    let v_out = PixelGrads {
        color: &v_color,
        alpha: Some(&v_alpha),
        depth: None,
        labels: None,
    };
    let (grads, screen) = reference::backward(&splats, &camera, &settings, &v_out);
    let checks: [(&str, Vec<f32>); 7] = [
        ("v_xy", flat2(&screen.v_means2d)),
        ("v_conics", flat3(&screen.v_conics)),
        ("v_means", flat3(&grads.v_means)),
        ("v_scales", flat3(&grads.v_log_scales)),
        ("v_quats", flat_quats_wxyz(&grads.v_rotations)),
        ("v_opacities", grads.v_raw_opacities.clone()),
        ("v_coeffs", grads.v_sh.clone()),
    ];
    for (key, got) in &checks {
        let want = case.get(key);
        let scale = want.iter().fold(0.0f32, |m, w| m.max(w.abs()));
        eprintln!("{name} {key}: scaled error {:.3e}", scaled_error(got, want));
        // `|a - b| <= 1e-5 · max|b| + 1e-3 |b|`, the fast path's bound against gsplat
        // (tests/gsplat_reference.rs). Measured for the reference: at most 2.7e-6 of the
        // tensor's largest magnitude (v_xy and v_means, tiny case), and 1.2e-4 relative among
        // values above 1 % of it (v_xy, tiny case): gsplat sums with float atomics, recovers T
        // by division and uses `__expf` (the fast path measured 1.1e-6 and 6.3e-5).
        assert_close(&format!("{name} {key}"), got, want, 1e-5 * scale, 1e-3);
    }
}

#[test]
fn reference_matches_gsplat_on_the_tiny_case() {
    reference_matches_gsplat(gsplat_support::CASES[0]);
}

#[test]
fn reference_matches_gsplat_on_the_basic_case() {
    reference_matches_gsplat(gsplat_support::CASES[1]);
}

// ---------------------------------------------------------------------------------------------
// The fast rasterizer against the reference.
// ---------------------------------------------------------------------------------------------

/// 150 × 97: neither side a multiple of 16, so the last tile column and row reach past the image.
fn random_camera() -> Camera {
    let k = Intrinsics {
        width: 150,
        height: 97,
        fx: 140.0,
        fy: 138.0,
        cx: 74.3,
        cy: 49.1,
    };
    Camera::look_at(
        k,
        Vec3::new(0.4, -0.6, -5.0),
        Vec3::new(0.0, 0.1, 0.0),
        Vec3::NEG_Y,
    )
}

/// A seeded scene of `n` Gaussians with [`LABELS`] label channels seen by [`random_camera`]:
/// most in a box before the camera, and a share of each kind that exercises a rule: behind the
/// near plane (culled), far off screen (culled), just outside the field of view but large
/// enough to reach into it (the Jacobian's 1.3 × fov clamp, where `J` uses the limit), huge
/// (a footprint over much of the image, opacity low enough not to hide the rest), tiny (below
/// a pixel, so the 0.3 px² blur dominates) and nearly opaque (alpha clamped, early stops).
fn random_scene(n: usize, seed: u64) -> Splats {
    let camera = random_camera();
    let to_world = |p_cam: Vec3| camera.rotation.inverse() * (p_cam - camera.translation);
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut u = |lo: f32, hi: f32| lo + (hi - lo) * rng.f32();
    let mut s = Splats::empty(3, LABELS);
    for g in 0..n {
        let kind = g % 20;
        let mut mean = Vec3::new(u(-2.0, 2.0), u(-1.5, 1.5), u(-1.5, 1.5));
        let mut log_scale =
            Vec3::splat(u(0.02, 0.2).ln()) + Vec3::new(u(0.0, 0.6), u(0.0, 0.6), u(0.0, 0.6));
        let mut opacity = u(0.05, 0.95);
        match kind {
            // Behind the camera, and between it and the near plane (z in (0, 0.01]).
            0 => mean = to_world(Vec3::new(u(-1.0, 1.0), u(-1.0, 1.0), u(-3.0, -0.1))),
            1 => mean = to_world(Vec3::new(u(-0.01, 0.01), u(-0.01, 0.01), u(0.0, 0.01))),
            // Far off screen to the side: culled by the on-screen test.
            2 => mean = to_world(Vec3::new(u(8.0, 12.0), u(-1.0, 1.0), u(3.0, 6.0))),
            // Beyond the clamp (|x / z| > about 0.7 here) but wide enough to reach the image.
            3 => {
                let side = if u(0.0, 1.0) < 0.5 { -1.0 } else { 1.0 };
                let z = u(3.5, 6.0);
                mean = to_world(Vec3::new(side * u(0.8, 1.0) * z, u(-0.5, 0.5), z));
                log_scale = Vec3::splat(u(0.6, 1.2).ln());
            }
            // Huge: a few units wide, near the camera.
            4 => {
                log_scale = Vec3::splat(u(1.0, 2.5).ln());
                opacity = u(0.05, 0.3);
            }
            // Tiny: well below a pixel.
            5 => log_scale = Vec3::splat(u(5e-4, 2e-3).ln()),
            // Nearly opaque: alpha clamped at alpha_max near the centre, and pixels behind a few
            // of them stop early.
            6..=9 => opacity = u(0.993, 0.9999),
            _ => {}
        }
        let q = Quat::from_xyzw(u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0));
        // Un-normalised on purpose: the gradient must chain through the normalisation.
        let q = q * (u(0.5, 2.0) / q.length());
        let mut sh = [0.0f32; 48];
        for (i, c) in sh.iter_mut().enumerate() {
            // DC colours in about [0.05, 0.95], some channels below the clamp at 0.
            *c = if i < 3 {
                u(-0.7, 0.6) / SH_C0
            } else {
                u(-0.2, 0.2)
            };
        }
        let labels = [u(-4.0, 4.0), u(-4.0, 4.0), u(-4.0, 4.0)];
        s.push(
            mean,
            log_scale,
            q,
            logit(opacity),
            &sh,
            &labels,
            g as u64,
            0,
        );
    }
    s
}

/// A tensor's error: its largest absolute difference relative to the tensor's largest
/// magnitude (the scale summation-order noise is relative to). NaN gives NaN.
fn scaled_error(got: &[f32], want: &[f32]) -> f32 {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(0.0f32, |m, w| m.max(w.abs()));
    let mut abs = 0.0f32;
    for (g, w) in got.iter().zip(want) {
        let e = (g - w).abs();
        if !(e <= abs) {
            abs = e;
        }
    }
    abs / scale.max(f32::MIN_POSITIVE)
}

/// Bounds on [`scaled_error`] between the fast rasterizer and the reference, per stage. The
/// largest errors measured over the gsplat scenes and the random scene (both thresholds), on
/// the AVX-512 build and on the AVX2 and baseline builds the rerun test runs:
/// - projection (means2d, conics, depths, colours, opacities, labels): 4.3e-7 (conics, tiny
///   case); depths and labels are bit-identical.
/// - images (colour, alpha, depth, label channels): 1.2e-6 (alpha, tiny case). The fast path's
///   `exp` is within 2 ulp of the standard library's (`fast_exp.rs`); no pixel of these scenes
///   had an alpha so close to the threshold, or a transmittance so close to 1e-4, that the two
///   decided differently (such a pixel would differ by about alpha · colour, over 1e-3).
/// - gradients (screen-space and per parameter): 3.3e-6 (v_log_scales, tiny case); the
///   reference sums per Gaussian in f64, the fast path in f32 in tile order.
const PROJECTION_BOUND: f32 = 2e-6;
const IMAGE_BOUND: f32 = 5e-6;
const GRADIENT_BOUND: f32 = 2e-5;

/// Runs both rasterizers on one scene, forward and backward (random weights on every output
/// as the pixel gradients), and checks every output and gradient against its bound.
fn compare_fast_with_reference(
    name: &str,
    splats: &Splats,
    camera: &Camera,
    settings: &RenderSettings,
    seed: u64,
) {
    let (r_out, r_p) = reference::render(splats, camera, settings);
    let mut fast = Rasterizer::new();
    let mut f_out = RenderOutput::default();
    fast.forward(splats, camera, settings, &mut f_out);
    let f_p: Projected = fast.projected().clone();
    assert_eq!(f_p.radii, r_p.radii, "{name}: radii (culling) differ");
    assert_eq!(
        f_p.color_pass, r_p.color_pass,
        "{name}: colour clamps differ"
    );
    let k = &camera.intrinsics;
    let w = Weights::random((k.width * k.height) as usize, splats.label_channels, seed);
    let mut f_g = SplatGrads::zeros(splats);
    fast.backward_pixels(splats, camera, settings, &w.pixel_grads(), &mut f_g);
    let f_s = fast.screen_grads();
    let (r_g, r_s) = reference::backward(splats, camera, settings, &w.pixel_grads());
    assert_eq!(f_g.visible, r_g.visible, "{name}: visible differs");

    let (pb, ib, gb) = (PROJECTION_BOUND, IMAGE_BOUND, GRADIENT_BOUND);
    let q = flat_quats_wxyz;
    let rows: Vec<(&str, Vec<f32>, Vec<f32>, f32)> = vec![
        ("means2d", flat2(&f_p.means2d), flat2(&r_p.means2d), pb),
        ("conics", flat3(&f_p.conics), flat3(&r_p.conics), pb),
        ("depths", f_p.depths.clone(), r_p.depths.clone(), pb),
        ("colors", flat3(&f_p.colors), flat3(&r_p.colors), pb),
        (
            "opacities",
            f_p.opacities.clone(),
            r_p.opacities.clone(),
            pb,
        ),
        ("labels", f_p.labels.clone(), r_p.labels.clone(), pb),
        ("color", f_out.color.clone(), r_out.color.clone(), ib),
        ("alpha", f_out.alpha.clone(), r_out.alpha.clone(), ib),
        ("depth", f_out.depth.clone(), r_out.depth.clone(), ib),
        (
            "label channels",
            f_out.labels.clone(),
            r_out.labels.clone(),
            ib,
        ),
        (
            "v_means2d",
            flat2(&f_s.v_means2d),
            flat2(&r_s.v_means2d),
            gb,
        ),
        ("v_conics", flat3(&f_s.v_conics), flat3(&r_s.v_conics), gb),
        ("v_colors", flat3(&f_s.v_colors), flat3(&r_s.v_colors), gb),
        (
            "v_opacities",
            f_s.v_opacities.clone(),
            r_s.v_opacities.clone(),
            gb,
        ),
        ("v_depths", f_s.v_depths.clone(), r_s.v_depths.clone(), gb),
        ("v_labels", f_s.v_labels.clone(), r_s.v_labels.clone(), gb),
        ("v_means", flat3(&f_g.v_means), flat3(&r_g.v_means), gb),
        (
            "v_log_scales",
            flat3(&f_g.v_log_scales),
            flat3(&r_g.v_log_scales),
            gb,
        ),
        ("v_rotations", q(&f_g.v_rotations), q(&r_g.v_rotations), gb),
        (
            "v_raw_opacities",
            f_g.v_raw_opacities.clone(),
            r_g.v_raw_opacities.clone(),
            gb,
        ),
        ("v_sh", f_g.v_sh.clone(), r_g.v_sh.clone(), gb),
        (
            "v_raw_labels",
            f_g.v_raw_labels.clone(),
            r_g.v_raw_labels.clone(),
            gb,
        ),
        (
            "v_means2d_norm",
            f_g.v_means2d_norm.clone(),
            r_g.v_means2d_norm.clone(),
            gb,
        ),
    ];
    let mut failures = Vec::new();
    for (what, fast, reference, bound) in &rows {
        let scaled = scaled_error(fast, reference);
        eprintln!("{name}: {what:>16}: scaled error {scaled:.3e} (bound {bound:.0e})");
        if !(scaled <= *bound) {
            failures.push(format!("{what}: {scaled:.3e} > {bound:.0e}"));
        }
    }
    assert!(failures.is_empty(), "{name}: {failures:?}");
}

fn with_labels(case: &Case, seed: u64) -> Splats {
    let mut rng = fastrand::Rng::with_seed(seed);
    case.splats_with_labels(LABELS, |_, _| rng.f32() * 8.0 - 4.0)
}

#[test]
fn fast_rasterizer_matches_the_reference_on_the_gsplat_scenes() {
    for (i, name) in gsplat_support::CASES.iter().enumerate() {
        let case = Case::load(name);
        let splats = with_labels(&case, i as u64);
        for sh_direction_grad in [false, true] {
            let settings = RenderSettings {
                background: Vec3::new(0.3, 0.1, 0.7),
                sh_direction_grad,
                ..gsplat_support::settings()
            };
            compare_fast_with_reference(
                name,
                &splats,
                &gsplat_support::camera(),
                &settings,
                10 + i as u64,
            );
        }
    }
}

/// What the random scene exercises, from the reference's own projection and blend: fails if a
/// change to [`random_scene`] stops covering a rule.
fn assert_random_scene_covers_every_rule(splats: &Splats, settings: &RenderSettings) {
    let camera = random_camera();
    let (_, projected) = reference::render(splats, &camera, settings);
    let radius = |g: usize| projected.radii[g];
    let kind = |k: usize| (0..splats.len()).filter(move |g| g % 20 == k);
    assert!(
        kind(0)
            .chain(kind(1))
            .chain(kind(2))
            .all(|g| radius(g) == 0)
    );
    let (w, h) = (camera.intrinsics.width, camera.intrinsics.height);
    let clamped_and_visible = kind(3)
        .filter(|&g| {
            let p = camera.world_to_camera(splats.means[g]);
            radius(g) > 0 && !(-0.7 * p.z..0.7 * p.z).contains(&p.x)
        })
        .count();
    assert!(
        clamped_and_visible >= 5,
        "{clamped_and_visible} clamped Gaussians visible"
    );
    assert!(
        kind(4).all(|g| radius(g) > w / 3),
        "huge ones span over a third of the image"
    );
    assert!(
        kind(5).all(|g| radius(g) > 0 && radius(g) <= 2),
        "tiny ones stay below 2 px"
    );
    let tiles = reference::TileLists::new(&projected, w, h);
    let (mut stopped, mut clamped_alpha) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let blend = reference::blend_pixel(&projected, &tiles, x, y, settings);
            stopped += blend.stopped as usize;
            clamped_alpha += blend
                .blended
                .iter()
                .filter(|b| b.raw_alpha > b.alpha)
                .count();
        }
    }
    eprintln!("{stopped} pixels stopped early, {clamped_alpha} blends clamped at alpha_max");
    assert!(stopped > 100 && clamped_alpha > 20);
}

#[test]
fn fast_rasterizer_matches_the_reference_on_a_random_scene() {
    let splats = random_scene(400, 7);
    let camera = random_camera();
    for alpha_threshold in [1.0 / 255.0, 0.0] {
        let settings = RenderSettings {
            background: Vec3::new(0.2, 0.5, 0.9),
            alpha_threshold,
            ..Default::default()
        };
        assert_random_scene_covers_every_rule(&splats, &settings);
        let name = format!("random, threshold {alpha_threshold}");
        compare_fast_with_reference(&name, &splats, &camera, &settings, 20);
    }
}

#[test]
fn simd_build_follows_the_environment() {
    damage_twin::simd::assert_level_follows_the_environment();
}

/// The fast rasterizer's comparisons with the kernels machines without AVX-512 or AVX2 run.
#[test]
fn fast_rasterizer_matches_the_reference_on_the_lower_simd_builds() {
    damage_twin::simd::rerun_tests_on_lower_builds(&[
        "simd_build_follows_the_environment",
        "fast_rasterizer_matches_the_reference_on_the_gsplat_scenes",
        "fast_rasterizer_matches_the_reference_on_a_random_scene",
    ]);
}

// ---------------------------------------------------------------------------------------------
// The reference against central finite differences of itself.
// ---------------------------------------------------------------------------------------------

fn tiny_camera() -> Camera {
    let k = Intrinsics {
        width: 40,
        height: 30,
        fx: 36.0,
        fy: 37.0,
        cx: 19.6,
        cy: 15.3,
    };
    Camera::look_at(
        k,
        Vec3::new(0.5, -0.4, -4.0),
        Vec3::new(0.0, 0.0, 0.2),
        Vec3::NEG_Y,
    )
}

/// Six Gaussians before [`tiny_camera`], each exercising a path of the backward: a plain one,
/// one beyond the Jacobian's clamp that still reaches the image, one below a pixel, one with a
/// colour channel held at 0 by the clamp, one opaque enough that its alpha is clamped at
/// `alpha_max` near its centre, and one small and in front of the others.
fn tiny_scene(seed: u64) -> Splats {
    let camera = tiny_camera();
    let to_world = |p_cam: Vec3| camera.rotation.inverse() * (p_cam - camera.translation);
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut u = |lo: f32, hi: f32| lo + (hi - lo) * rng.f32();
    let mut s = Splats::empty(3, LABELS);
    for g in 0..6 {
        let z = u(3.5, 4.5);
        let mut p_cam = Vec3::new(u(-0.8, 0.8), u(-0.6, 0.6), z);
        let mut log_scale = Vec3::new(u(0.1, 0.4).ln(), u(0.1, 0.4).ln(), u(0.1, 0.4).ln());
        let mut opacity = u(0.3, 0.8);
        let mut sh = [0.0f32; 48];
        for (i, c) in sh.iter_mut().enumerate() {
            *c = if i < 3 {
                u(-0.3, 0.4) / SH_C0
            } else {
                u(-0.15, 0.15)
            };
        }
        match g {
            // |x / z| above the limit (about 0.84 here), wide enough to reach the image.
            1 => {
                p_cam.x = 1.0 * z;
                log_scale = Vec3::new(0.8, 0.5, 0.6).ln();
            }
            2 => log_scale = Vec3::new(2e-3, 3e-3, 1e-3).ln(),
            3 => sh[1] = -2.0 / SH_C0,
            4 => opacity = 0.995,
            5 => {
                p_cam.z = 2.5;
                log_scale = Vec3::new(0.08, 0.12, 0.05).ln();
            }
            _ => {}
        }
        let q = Quat::from_xyzw(u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0));
        let q = q * (u(0.5, 2.0) / q.length());
        let labels = [u(-2.0, 2.0), u(-2.0, 2.0), u(-2.0, 2.0)];
        s.push(
            to_world(p_cam),
            log_scale,
            q,
            logit(opacity),
            &sh,
            &labels,
            g as u64,
            0,
        );
    }
    s
}

/// A parameter lane: one f32 of the splats.
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
    fn value(self, s: &mut Splats) -> &mut f32 {
        match self {
            Lane::Mean(g, a) => &mut s.means[g][a],
            Lane::LogScale(g, a) => &mut s.log_scales[g][a],
            Lane::Rotation(g, 0) => &mut s.rotations[g].x,
            Lane::Rotation(g, 1) => &mut s.rotations[g].y,
            Lane::Rotation(g, 2) => &mut s.rotations[g].z,
            Lane::Rotation(g, _) => &mut s.rotations[g].w,
            Lane::Opacity(g) => &mut s.raw_opacities[g],
            Lane::Sh(i) => &mut s.sh[i],
            Lane::Label(i) => &mut s.raw_labels[i],
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

    /// Steps: the loss is an f32 rendering summed in f64, whose rounding noise (about 1e-6
    /// absolute here) divided by 2 eps must stay below the gradients' floor, while the step
    /// stays small beside the Gaussians' sizes (0.05 and up, but for the tiny one).
    fn eps(self) -> f32 {
        match self {
            Lane::Sh(_) | Lane::Label(_) => 1e-2,
            _ => 2e-3,
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

fn all_lanes(splats: &Splats) -> Vec<Lane> {
    let mut lanes = Vec::new();
    for g in 0..splats.len() {
        for a in 0..3 {
            lanes.push(Lane::Mean(g, a));
            lanes.push(Lane::LogScale(g, a));
        }
        lanes.extend((0..4).map(|a| Lane::Rotation(g, a)));
        lanes.push(Lane::Opacity(g));
    }
    lanes.extend((0..splats.sh.len()).map(Lane::Sh));
    lanes.extend((0..splats.raw_labels.len()).map(Lane::Label));
    lanes
}

/// Finite-difference tolerance: `|fd - analytic| <= REL · max(|fd|, |analytic|) + FLOOR · rms`
/// (rms: the kind's RMS gradient over the scene). Measured on both seeds: the worst
/// `|fd - analytic| / tolerance` was 0.54 (rotations, seed 2; means 0.21, log-scales 0.28,
/// opacities 0.39, SH 0.23, labels 0.02), i.e. errors of about 1.6e-3 relative plus 2.7e-4 of
/// the RMS: the f32 rendering's rounding noise over the step. A tolerance 5x tighter than
/// the fast path's finite-difference test (`tests/raster_gradients.rs`: 2 % + 2e-3 rms).
const REL: f64 = 3e-3;
const FLOOR: f64 = 5e-4;

#[test]
fn reference_gradients_match_central_finite_differences() {
    let camera = tiny_camera();
    // No alpha threshold: its skip is a true discontinuity of the image (see raster_gradients).
    let settings = RenderSettings {
        background: Vec3::new(0.2, 0.5, 0.9),
        alpha_threshold: 0.0,
        ..Default::default()
    };
    for seed in [1u64, 2] {
        let splats = tiny_scene(seed);
        let k = &camera.intrinsics;
        let w = Weights::random((k.width * k.height) as usize, LABELS, seed + 100);
        let (_, projected) = reference::render(&splats, &camera, &settings);
        assert!(projected.radii.iter().all(|&r| r > 0), "all six visible");
        let (grads, _) = reference::backward(&splats, &camera, &settings, &w.pixel_grads());
        let lanes = all_lanes(&splats);
        let mut rms = [0.0f64; 6];
        let mut count = [0usize; 6];
        for lane in &lanes {
            rms[lane.kind()] += (lane.grad(&grads) as f64).powi(2);
            count[lane.kind()] += 1;
        }
        for k in 0..6 {
            rms[k] = (rms[k] / count[k].max(1) as f64).sqrt();
        }
        let loss = |s: &Splats| w.loss(&reference::render(s, &camera, &settings).0);
        let mut worst = [0.0f64; 6];
        let mut failures = Vec::new();
        let (mut significant, mut caught) = (0, 0);
        for &lane in &lanes {
            let analytic = lane.grad(&grads) as f64;
            let mut s = splats.clone();
            let x = *lane.value(&mut s);
            let (xp, xm) = (x + lane.eps(), x - lane.eps());
            *lane.value(&mut s) = xp;
            let lp = loss(&s);
            *lane.value(&mut s) = xm;
            let lm = loss(&s);
            let fd = (lp - lm) / (xp as f64 - xm as f64);
            // Within REL of the larger of the two, plus an absolute floor per kind for the f32
            // rendering noise: FLOOR of its RMS gradient.
            let floor = FLOOR * rms[lane.kind()];
            let tolerance = |a: f64| REL * a.abs().max(fd.abs()) + floor;
            let ratio = (fd - analytic).abs() / tolerance(analytic);
            worst[lane.kind()] = worst[lane.kind()].max(ratio);
            if !(ratio <= 1.0) {
                failures.push(format!(
                    "seed {seed} {lane:?}: analytic {analytic:.6e}, fd {fd:.6e}, floor {floor:.1e}"
                ));
            }
            // The check must notice a gradient 5 % off wherever the gradient is well above the
            // floor.
            if analytic.abs() > 25.0 * floor {
                significant += 1;
                let wrong = 1.05 * analytic;
                caught += !((fd - wrong).abs() <= tolerance(wrong)) as usize;
            }
        }
        for k in 0..6 {
            eprintln!(
                "seed {seed} {:>13}: rms {:.3e}, worst |fd - analytic| / tolerance {:.3}",
                KINDS[k], rms[k], worst[k]
            );
        }
        eprintln!(
            "seed {seed}: {} lanes, a 5 % error caught on {caught} of {significant} significant lanes",
            lanes.len()
        );
        for f in &failures {
            eprintln!("MISMATCH {f}");
        }
        assert!(failures.is_empty(), "{} lanes disagree", failures.len());
        assert!(rms.iter().all(|&r| r > 0.0), "every kind has gradients");
        assert_eq!(
            caught, significant,
            "a 5 % gradient error must fail the check"
        );
    }
}
