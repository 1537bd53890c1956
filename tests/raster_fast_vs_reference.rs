//! The fast `Rasterizer` against the plain reference (`damage_twin::raster::reference`), forward
//! and backward, every output and every gradient (labels with 3 channels, depth and alpha
//! gradients through `backward_pixels`): on gsplat's two scenes with label channels added, and
//! on a seeded random scene with Gaussians behind the near plane, off screen, in the Jacobian's
//! clamp, huge, tiny and nearly opaque, at an image size that is not a multiple of 16, with the
//! default alpha threshold and with none; on every SIMD build the CPU has.
//!
//! The reference itself is checked against gsplat and finite differences in
//! `tests/raster_reference.rs`. Each bound was set from the largest error measured (written
//! beside it; `cargo test --test raster_fast_vs_reference -- --nocapture` prints them).

mod raster_support;
mod shared_data;

use damage_twin::raster::reference;
use damage_twin::raster::{Projected, Rasterizer, RenderOutput, RenderSettings, SplatGrads};
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use damage_twin::splats::model::{SH_C0, logit};
use glam::{Quat, Vec3};
use raster_support::{Case, Weights, flat_quats_wxyz, flat2, flat3, scaled_error};

const LABELS: usize = 3;

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
    for (i, name) in raster_support::CASES.iter().enumerate() {
        let Some(case) = Case::load(name) else { return };
        let splats = with_labels(&case, i as u64);
        for sh_direction_grad in [false, true] {
            let settings = RenderSettings {
                background: Vec3::new(0.3, 0.1, 0.7),
                sh_direction_grad,
                ..raster_support::settings()
            };
            compare_fast_with_reference(
                name,
                &splats,
                &raster_support::camera(),
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
