//! The GPU forward pass against external and large references: gsplat's own renders of the brush
//! test scenes (`../shared/data/brush_gsplat_reference`, see its SOURCE.md), a random scene
//! against the plain CPU reference (`raster::reference`), and a 100k-Gaussian scene against the
//! CPU rasterizer.

mod gpu_support;
mod shared_data;

use glam::{Quat, Vec3};
use safetensors::SafeTensors;

use damage_twin::gpu::{GpuRenderSettings, GpuRenderer};
use damage_twin::raster::{Rasterizer, RenderOutput, RenderSettings, reference};
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use gpu_support::{camera, context, diff_stats, random_splats};

fn floats(st: &SafeTensors<'_>, name: &str) -> Vec<f32> {
    let t = st
        .tensor(name)
        .unwrap_or_else(|e| panic!("tensor {name}: {e}"));
    assert_eq!(t.dtype(), safetensors::Dtype::F32, "{name}");
    bytemuck::pod_collect_to_vec(t.data())
}

/// One reference file: its scene and gsplat's image (RGBA) and intermediates.
struct Reference {
    splats: Splats,
    camera: Camera,
    out_img: Vec<f32>,
    xys: Vec<f32>,
    conics: Vec<f32>,
    depths: Vec<f32>,
}

/// The scene of one reference file: raw parameters (gsplat's quaternion order w, x, y, z); `None`
/// (the test skips) when the reference data is missing.
fn load_case(file: &str) -> Option<Reference> {
    let path = shared_data::path(&format!("brush_gsplat_reference/{file}"))?;
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let means = floats(&st, "means");
    let scales = floats(&st, "scales");
    let quats = floats(&st, "quats");
    let opacities = floats(&st, "opacities");
    let coeffs = floats(&st, "coeffs");
    let n = opacities.len();
    let mut splats = Splats::empty(3, 0);
    for g in 0..n {
        let q = &quats[4 * g..4 * g + 4];
        splats.push(
            Vec3::from_slice(&means[3 * g..3 * g + 3]),
            Vec3::from_slice(&scales[3 * g..3 * g + 3]),
            Quat::from_xyzw(q[1], q[2], q[3], q[0]),
            opacities[g],
            &coeffs[48 * g..48 * g + 48],
            &[],
            g as u64,
            0,
        );
    }
    let (w, h) = (123u32, 82u32);
    let k = Intrinsics {
        width: w,
        height: h,
        fx: w as f32 / 2.0,
        fy: w as f32 / 2.0,
        cx: w as f32 / 2.0,
        cy: h as f32 / 2.0,
    };
    let position = Vec3::new(0.123, 0.456, -8.0);
    let camera = Camera::new(k, Quat::IDENTITY, -position);
    Some(Reference {
        splats,
        camera,
        out_img: floats(&st, "out_img"),
        xys: floats(&st, "xys"),
        conics: floats(&st, "conics"),
        depths: floats(&st, "depths"),
    })
}

fn check_case(file: &str) {
    let Some(Reference {
        splats,
        camera,
        out_img,
        xys,
        conics,
        depths,
    }) = load_case(file)
    else {
        return;
    };
    let ctx = context();
    // gsplat clamps alpha at 0.999 and has no background.
    let settings = GpuRenderSettings {
        background: Vec3::ZERO,
        sh_degree: 3,
        alpha_max: 0.999,
        sh_direction_grad: false,
    };
    let mut gpu = GpuRenderer::new(&ctx).unwrap();
    gpu.upload(&splats).unwrap();
    let frame = gpu.render_to_image(&camera, &settings).unwrap();
    let projected = gpu.read_projected().unwrap();
    let mut compared = 0;
    for (g, p) in projected.iter().enumerate() {
        if p.radius == 0 {
            continue;
        }
        compared += 1;
        for c in 0..2 {
            let want = xys[2 * g + c];
            assert!(
                (p.xy[c] - want).abs() < 1e-3,
                "{file}: xy {g}: {:?} vs {want}",
                p.xy
            );
        }
        for c in 0..3 {
            let want = conics[3 * g + c];
            assert!(
                (p.conic[c] - want).abs() <= 1e-5 + 1e-3 * want.abs(),
                "{file}: conic {g}: {:?} vs {want}",
                p.conic
            );
        }
        assert!((p.depth - depths[g]).abs() < 1e-4, "{file}: depth {g}");
    }
    assert!(compared > 0, "{file}: nothing visible");
    // brush's own tolerance for this comparison: |a - b| < 1e-5 + 1e-2 |b| per value.
    let pixels = (frame.width * frame.height) as usize;
    let mut worst = 0.0f32;
    for p in 0..pixels {
        for c in 0..4 {
            let got = if c < 3 {
                frame.color[3 * p + c]
            } else {
                frame.alpha[p]
            };
            let want = out_img[4 * p + c];
            let excess = (got - want).abs() - (1e-5 + 1e-2 * want.abs());
            assert!(
                excess <= 0.0,
                "{file}: pixel {p} channel {c}: {got} vs {want}"
            );
            worst = worst.max((got - want).abs());
        }
    }
    eprintln!("{file}: {compared} visible Gaussians, worst pixel difference {worst}");
}

#[test]
fn tiny_case_matches_gsplat() {
    check_case("tiny_case.safetensors");
}

#[test]
fn basic_case_matches_gsplat() {
    check_case("basic_case.safetensors");
}

#[test]
fn hundred_thousand_gaussians_match_cpu_image_statistics() {
    let ctx = context();
    let splats = random_splats(100_000, 0, 42);
    let cam = camera(320, 200);
    let settings = RenderSettings::new(Vec3::new(0.5, 0.5, 0.5), 3);
    let mut raster = Rasterizer::new();
    let mut cpu = RenderOutput::default();
    raster.forward(&splats, &cam, &settings, &mut cpu);
    let mut gpu = GpuRenderer::new(&ctx).unwrap();
    gpu.upload(&splats).unwrap();
    let frame = gpu
        .render_to_image(&cam, &GpuRenderSettings::from(&settings))
        .unwrap();
    assert_eq!(
        gpu.read_intersection_count().unwrap() as usize,
        raster.tile_bins().0.len()
    );
    let (max, mean) = diff_stats(&frame.color, &cpu.color);
    let mse: f64 = frame
        .color
        .iter()
        .zip(&cpu.color)
        .map(|(a, b)| ((a - b) as f64).powi(2))
        .sum::<f64>()
        / cpu.color.len() as f64;
    let psnr = 10.0 * (1.0 / mse.max(1e-20)).log10();
    eprintln!("100k: max {max} mean {mean} psnr {psnr:.1} dB");
    // Thousands of Gaussians per tile accumulate rounding; measured on lavapipe (docs/GPU.md).
    assert!(mean < 1e-4, "mean abs difference {mean}");
    assert!(psnr > 60.0, "PSNR {psnr}");
    assert!(max < 0.05, "max abs difference {max}");
}

/// The GPU's projection and image against the plain reference, on a random scene with three
/// label channels at an image size that is not a multiple of 16 (the GPU's alpha threshold is
/// the default 1/255).
#[test]
fn forward_matches_the_plain_reference_on_a_random_scene() {
    let ctx = context();
    let splats = random_splats(3000, 3, 8);
    let cam = camera(150, 97);
    let settings = RenderSettings::new(Vec3::new(0.2, 0.4, 0.9), 3);
    let (want, want_projected) = reference::render(&splats, &cam, &settings);
    let mut gpu = GpuRenderer::new(&ctx).unwrap();
    gpu.upload(&splats).unwrap();
    let frame = gpu
        .render_to_image(&cam, &GpuRenderSettings::from(&settings))
        .unwrap();
    let projected = gpu.read_projected().unwrap();
    let (mut visible, mut radius_off_by_one) = (0, 0);
    let (mut worst_xy, mut worst_conic, mut worst_color) = (0.0f32, 0.0f32, 0.0f32);
    for (g, p) in projected.iter().enumerate().take(splats.len()) {
        // The same Gaussians culled; `ceil(3 sigma)` may round to the next pixel now and then.
        let radius = want_projected.radii[g];
        assert!(
            p.radius.abs_diff(radius) <= 1 && (p.radius == 0) == (radius == 0),
            "Gaussian {g}: radius {} vs {radius}",
            p.radius
        );
        if radius == 0 {
            continue;
        }
        visible += 1;
        radius_off_by_one += (p.radius != radius) as usize;
        let m = want_projected.means2d[g];
        worst_xy = worst_xy
            .max((p.xy[0] - m.x).abs())
            .max((p.xy[1] - m.y).abs());
        let c = want_projected.conics[g];
        for (a, b) in p.conic.iter().zip([c.x, c.y, c.z]) {
            worst_conic = worst_conic.max((a - b).abs() / (1.0 + b.abs()));
        }
        let col = want_projected.colors[g];
        for (a, b) in p.color.iter().zip([col.x, col.y, col.z]) {
            worst_color = worst_color.max((a - b).abs());
        }
        assert!((p.depth - want_projected.depths[g]).abs() <= 1e-5 * want_projected.depths[g]);
        assert!((p.opacity - want_projected.opacities[g]).abs() < 1e-6);
    }
    let (c_max, c_mean) = diff_stats(&frame.color, &want.color);
    let (a_max, _) = diff_stats(&frame.alpha, &want.alpha);
    let (d_max, _) = diff_stats(&frame.depth, &want.depth);
    let (l_max, _) = diff_stats(&frame.labels, &want.labels);
    eprintln!(
        "{visible} visible ({radius_off_by_one} radii off by one); xy {worst_xy:.3e}, conic {worst_conic:.3e}, colour {worst_color:.3e}; \
         image colour max {c_max:.3e} mean {c_mean:.3e}, alpha {a_max:.3e}, depth {d_max:.3e}, \
         labels {l_max:.3e}"
    );
    // Bounds from the largest differences measured on lavapipe, with margins: means 1.5e-5 px
    // (on coordinates up to 150), conics 5.2e-7 relative, colours 1.2e-7; image colour 6.6e-7
    // (mean 7.3e-8), alpha 7.2e-7, depth 2.4e-6 (on depths up to 7), labels 1.2e-6. Both use the
    // standard `exp` (the CPU rasterizer's 2-ulp `fast_exp` is what gpu_stages.rs allows 2e-3
    // for) and no pixel decided the threshold or the stop differently.
    assert!(visible > 1000, "only {visible} visible");
    assert!(
        radius_off_by_one * 100 <= visible,
        "{radius_off_by_one} radii off by one"
    );
    assert!(worst_xy < 1e-4, "means2d differ by {worst_xy}");
    assert!(worst_conic < 5e-6, "conics differ by {worst_conic}");
    assert!(worst_color < 1e-6, "colours differ by {worst_color}");
    assert!(
        c_max < 5e-6 && c_mean < 5e-7,
        "image colour max {c_max} mean {c_mean}"
    );
    assert!(a_max < 5e-6, "alpha {a_max}");
    assert!(d_max < 2e-5, "depth {d_max}");
    assert!(l_max < 1e-5, "labels {l_max}");
}
