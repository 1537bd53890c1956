//! The GPU backward (rasterize and project backward kernels, through `GpuBackend`) against the
//! CPU: gsplat's own gradients on brush's two reference scenes, and the CPU rasterizer's exact
//! backward on a random scene with label channels, alpha and depth gradients, SH degree 3 and the
//! SH view-direction path, with both ways of accumulating (float atomics and compare-and-swap).
//! Runs on lavapipe in CI (a missing adapter fails).

mod gpu_support;
mod raster_support;
mod shared_data;

use damage_twin::gpu::GpuBackend;
use damage_twin::raster::{
    PixelGrads, RasterBackend, Rasterizer, RenderOutput, RenderSettings, SplatGrads,
};
use damage_twin::scene::Camera;
use damage_twin::splats::Splats;
use glam::Vec3;
use raster_support::{Case, Weights, assert_close, flat_quats_wxyz, flat3, scaled_error};

fn backends() -> Vec<GpuBackend> {
    let ctx = gpu_support::context();
    let mut all = vec![GpuBackend::with_accumulation(&ctx, false).unwrap()];
    if ctx.capabilities.float32_atomics {
        all.push(GpuBackend::with_accumulation(&ctx, true).unwrap());
    }
    all
}

fn run(
    backend: &mut dyn RasterBackend,
    splats: &Splats,
    camera: &Camera,
    settings: &RenderSettings,
    v_out: &PixelGrads,
) -> (RenderOutput, SplatGrads) {
    let mut out = RenderOutput::default();
    backend.forward(splats, camera, settings, &mut out);
    let mut grads = SplatGrads::zeros(splats);
    backend.backward(splats, camera, settings, v_out, &mut grads);
    assert_eq!(backend.fault(), None);
    (out, grads)
}

/// Per parameter, the largest error relative to the CPU tensor's largest magnitude.
fn compare(what: &str, gpu: &SplatGrads, cpu: &SplatGrads, tolerance: f32) {
    let tensors: [(&str, Vec<f32>, Vec<f32>); 7] = [
        ("v_means", flat3(&gpu.v_means), flat3(&cpu.v_means)),
        (
            "v_log_scales",
            flat3(&gpu.v_log_scales),
            flat3(&cpu.v_log_scales),
        ),
        (
            "v_rotations",
            flat_quats_wxyz(&gpu.v_rotations),
            flat_quats_wxyz(&cpu.v_rotations),
        ),
        (
            "v_raw_opacities",
            gpu.v_raw_opacities.clone(),
            cpu.v_raw_opacities.clone(),
        ),
        ("v_sh", gpu.v_sh.clone(), cpu.v_sh.clone()),
        (
            "v_raw_labels",
            gpu.v_raw_labels.clone(),
            cpu.v_raw_labels.clone(),
        ),
        (
            "v_means2d_norm",
            gpu.v_means2d_norm.clone(),
            cpu.v_means2d_norm.clone(),
        ),
    ];
    for (name, got, want) in &tensors {
        let error = scaled_error(got, want);
        eprintln!("{what} {name}: scaled error {error:.2e}");
        assert!(
            error <= tolerance,
            "{what} {name}: error {error:.3e} relative to the largest CPU gradient (tolerance {tolerance:.0e})"
        );
    }
    assert_eq!(gpu.visible, cpu.visible, "{what}: visible Gaussians differ");
}

// Measured on lavapipe (`cargo test --test gpu_backward -- --nocapture` prints them): largest
// scaled errors 2.0e-6 (v_rotations), 3–6e-7 for the rest, both accumulations. The tolerance
// leaves 25× headroom for summation order (hundreds of pixels add into one Gaussian in any order
// on a GPU) and T recovered by division back to front, and is far below a real mistake.
const RANDOM_SCENE_TOLERANCE: f32 = 5e-5;

#[test]
fn random_scene_gradients_match_the_cpu_backward() {
    let splats = gpu_support::random_splats(300, 3, 11);
    let camera = gpu_support::camera(72, 40);
    let weights = Weights::random(72 * 40, 3, 5);
    let mut cpu_means = Vec::new();
    for sh_direction_grad in [true, false] {
        let settings = RenderSettings {
            background: Vec3::new(0.2, 0.4, 0.6),
            sh_direction_grad,
            ..RenderSettings::default()
        };
        let mut cpu_raster = Rasterizer::new();
        let (cpu_out, cpu) = run(
            &mut cpu_raster,
            &splats,
            &camera,
            &settings,
            &weights.pixel_grads(),
        );
        assert!(cpu.visible.iter().filter(|&&v| v).count() > 100);
        cpu_means.push(flat3(&cpu.v_means));
        for mut backend in backends() {
            let what = format!(
                "{} sh_direction_grad={sh_direction_grad}",
                backend.describe()
            );
            let (out, gpu) = run(
                &mut backend,
                &splats,
                &camera,
                &settings,
                &weights.pixel_grads(),
            );
            assert!(
                scaled_error(&out.color, &cpu_out.color) < 1e-4,
                "{what}: forward differs"
            );
            compare(&what, &gpu, &cpu, RANDOM_SCENE_TOLERANCE);
            assert_eq!(
                backend.radii(),
                &cpu_raster.projected().radii[..],
                "{what}: radii"
            );
        }
    }
    // The view-direction path changes the means' gradients well beyond the tolerance, so the
    // comparison above tells the two settings apart.
    assert!(scaled_error(&cpu_means[1], &cpu_means[0]) > 20.0 * RANDOM_SCENE_TOLERANCE);
}

/// The GPU backward against gsplat's gradients, as `gsplat_reference.rs` checks the CPU.
fn check_gsplat_case(name: &str) {
    let Some(case) = Case::load(name) else { return };
    let splats = case.splats();
    let (v_color, v_alpha) = case.pixel_grads();
    let v_out = PixelGrads {
        color: &v_color,
        alpha: Some(&v_alpha),
        depth: None,
        labels: None,
    };
    for mut backend in backends() {
        let (_, grads) = run(
            &mut backend,
            &splats,
            &raster_support::camera(),
            &raster_support::settings(),
            &v_out,
        );
        let checks: [(&str, Vec<f32>); 4] = [
            ("v_means", flat3(&grads.v_means)),
            ("v_scales", flat3(&grads.v_log_scales)),
            ("v_quats", flat_quats_wxyz(&grads.v_rotations)),
            ("v_opacities", grads.v_raw_opacities.clone()),
        ];
        for (key, got) in &checks {
            let want = case.get(key);
            let scale = want.iter().fold(0.0f32, |m, w| m.max(w.abs()));
            // gsplat_reference.rs's tolerances for the CPU.
            assert_close(
                &format!("{} {name} {key}", backend.describe()),
                got,
                want,
                1e-5 * scale,
                1e-3,
            );
        }
        assert_close(
            &format!("{} {name} v_coeffs", backend.describe()),
            &grads.v_sh,
            case.get("v_coeffs"),
            1e-5 * case
                .get("v_coeffs")
                .iter()
                .fold(0.0f32, |m, w| m.max(w.abs())),
            1e-3,
        );
    }
}

#[test]
fn tiny_case_gradients_match_gsplat() {
    check_gsplat_case("tiny_case.safetensors");
}

#[test]
fn basic_case_gradients_match_gsplat() {
    check_gsplat_case("basic_case.safetensors");
}
