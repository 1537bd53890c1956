//! The CPU rasterizer against gsplat's own forward render, intermediates and gradients for the
//! 4- and 16-Gaussian scenes of brush's test cases (../shared/data/brush_gsplat_reference,
//! SOURCE.md: 123×82, fx = fy = 61.5, camera at (0.123, 0.456, -8), identity rotation).

mod raster_support;
mod shared_data;

use damage_twin::raster::{PixelGrads, Rasterizer, RenderOutput, SplatGrads};
use damage_twin::splats::Splats;
use raster_support::{Case, assert_close, camera, flat_quats_wxyz, flat2, flat3, settings};

fn forward(case: &Case) -> (Rasterizer, RenderOutput, Splats) {
    let splats = case.splats();
    let mut raster = Rasterizer::new();
    let mut out = RenderOutput::default();
    raster.forward(&splats, &camera(), &settings(), &mut out);
    (raster, out, splats)
}

fn check_forward(name: &str) {
    let Some(case) = Case::load(name) else { return };
    let (raster, out, _) = forward(&case);
    let mut rgba = Vec::with_capacity(out.alpha.len() * 4);
    for p in 0..out.alpha.len() {
        rgba.extend_from_slice(&out.color[p * 3..p * 3 + 3]);
        rgba.push(out.alpha[p]);
    }
    assert_close(
        &format!("{name} out_img"),
        &rgba,
        case.get("out_img"),
        1e-5,
        1e-2,
    );
    let p = raster.projected();
    let xys = flat2(&p.means2d);
    let conics = flat3(&p.conics);
    assert_close(&format!("{name} xys"), &xys, case.get("xys"), 1e-5, 1e-2);
    assert_close(
        &format!("{name} conics"),
        &conics,
        case.get("conics"),
        1e-5,
        1e-2,
    );
    assert_close(
        &format!("{name} depths"),
        &p.depths,
        case.get("depths"),
        1e-5,
        1e-2,
    );
    assert!(
        p.radii.iter().all(|&r| r > 0),
        "every reference Gaussian is visible"
    );
}

#[test]
fn tiny_case_forward_matches_gsplat() {
    check_forward("tiny_case.safetensors");
}

#[test]
fn basic_case_forward_matches_gsplat() {
    check_forward("basic_case.safetensors");
}

fn check_gradients(name: &str, tol: &GradTolerances) {
    let Some(case) = Case::load(name) else { return };
    let (mut raster, _out, splats) = forward(&case);
    let (v_color, v_alpha) = case.pixel_grads();
    let mut grads = SplatGrads::zeros(&splats);
    let v_out = PixelGrads {
        color: &v_color,
        alpha: Some(&v_alpha),
        depth: None,
        labels: None,
    };
    raster.backward_pixels(&splats, &camera(), &settings(), &v_out, &mut grads);
    let screen = raster.screen_grads();
    let v_xy = flat2(&screen.v_means2d);
    let v_quats = flat_quats_wxyz(&grads.v_rotations);
    let checks: [(&str, Vec<f32>, f32, f32); 7] = [
        ("v_xy", v_xy, tol.atol, tol.rtol),
        ("v_conics", flat3(&screen.v_conics), tol.atol, tol.rtol),
        ("v_means", flat3(&grads.v_means), tol.atol, tol.rtol),
        ("v_scales", flat3(&grads.v_log_scales), tol.atol, tol.rtol),
        ("v_quats", v_quats, tol.atol, tol.rtol),
        (
            "v_opacities",
            grads.v_raw_opacities.clone(),
            tol.atol,
            tol.rtol,
        ),
        ("v_coeffs", grads.v_sh.clone(), tol.atol, tol.rtol),
    ];
    for (key, got, atol, rtol) in &checks {
        let want = case.get(key);
        let scale = want.iter().fold(0.0f32, |m, w| m.max(w.abs()));
        eprintln!("{name} {key}: largest |gsplat| {scale:.3e}");
        assert_close(&format!("{name} {key}"), got, want, atol * scale, *rtol);
    }
}

/// Gradient tolerance: `|a - b| <= atol · max|b| + rtol·|b|` (atol relative to the tensor).
struct GradTolerances {
    atol: f32,
    rtol: f32,
}

// Measured on both cases (`cargo test --test gsplat_reference -- --nocapture` prints them):
// largest error relative to the tensor's largest magnitude 1.1e-6 (v_conics, basic case), and
// largest relative error of values above 1 % of that magnitude 6.3e-5 (v_xy, tiny case). They
// are not 1e-7 because gsplat sums with float atomics in arbitrary order, recovers T by division
// back to front (we replay front to back), and uses `__expf`. The tolerance keeps ~10x headroom
// over those maxima and is still 100x tighter than any real bug we found (a misplaced T in the
// suffix term gave 4 % errors on v_xy in the basic case and passed the tiny one).
const GRAD_TOL: GradTolerances = GradTolerances {
    atol: 1e-5,
    rtol: 1e-3,
};

#[test]
fn tiny_case_gradients_match_gsplat() {
    check_gradients("tiny_case.safetensors", &GRAD_TOL);
}

#[test]
fn basic_case_gradients_match_gsplat() {
    check_gradients("basic_case.safetensors", &GRAD_TOL);
}

#[test]
fn simd_build_follows_the_environment() {
    damage_twin::simd::assert_level_follows_the_environment();
}

/// The same checks with the kernels machines without AVX-512 or AVX2 run.
#[test]
fn gsplat_checks_pass_on_the_lower_simd_builds() {
    // Without the reference the reruns would only skip again.
    if shared_data::path("brush_gsplat_reference").is_none() {
        return;
    }
    damage_twin::simd::rerun_tests_on_lower_builds(&[
        "simd_build_follows_the_environment",
        "tiny_case_forward_matches_gsplat",
        "basic_case_forward_matches_gsplat",
        "tiny_case_gradients_match_gsplat",
        "basic_case_gradients_match_gsplat",
    ]);
}
