//! The plain reference rasterizer (`damage_twin::raster::reference`) against gsplat's own
//! tensors (forward image, projected means, conics and depths, every gradient), against central
//! finite differences of itself (every parameter lane, through colour, alpha, depth and label
//! outputs, the SH view direction included), and its rules on hand-made cases. The fast
//! rasterizer is compared with it in `tests/raster_fast_vs_reference.rs`.
//!
//! Each tolerance was set from the largest error measured (written beside it;
//! `cargo test --test raster_reference -- --nocapture` prints them).

mod raster_support;
mod shared_data;

use damage_twin::raster::reference;
use damage_twin::raster::{PixelGrads, RenderSettings, SplatGrads};
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use damage_twin::splats::model::{SH_C0, logit};
use glam::{Quat, Vec3};
use raster_support::{Case, Weights, assert_close, flat_quats_wxyz, flat2, flat3, scaled_error};

const LABELS: usize = 3;

// ---------------------------------------------------------------------------------------------
// The reference against gsplat.
// ---------------------------------------------------------------------------------------------

fn reference_matches_gsplat(name: &str) {
    let Some(case) = Case::load(name) else { return };
    let splats = case.splats();
    let (camera, settings) = (raster_support::camera(), raster_support::settings());
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
    reference_matches_gsplat(raster_support::CASES[0]);
}

#[test]
fn reference_matches_gsplat_on_the_basic_case() {
    reference_matches_gsplat(raster_support::CASES[1]);
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

// ---------------------------------------------------------------------------------------------
// The reference's rules on hand-made cases.
// ---------------------------------------------------------------------------------------------

/// A projected frame of Gaussians given by `(mean2d, conic, depth, radius, opacity)`, white,
/// without labels.
fn hand_made(gaussians: &[(glam::Vec2, Vec3, f32, u32, f32)]) -> damage_twin::raster::Projected {
    let mut p = damage_twin::raster::Projected::default();
    for &(mean2d, conic, depth, radius, opacity) in gaussians {
        p.means2d.push(mean2d);
        p.conics.push(conic);
        p.depths.push(depth);
        p.radii.push(radius);
        p.colors.push(Vec3::ONE);
        p.color_pass.push(7);
        p.opacities.push(opacity);
        p.extents.push(glam::Vec2::splat(f32::INFINITY));
    }
    p
}

#[test]
fn an_isotropic_gaussian_on_the_axis_projects_to_the_textbook_footprint() {
    // Camera at the origin looking along +z, fx = fy = 100; the Gaussian 5 ahead with σ = 0.1:
    // σ_px = 100 · 0.1 / 5 = 2 px, so Σ' = (4 + 0.3) I (eq. 5 plus the blur) and the radius is
    // ceil(3 sqrt(4.3 + 0.1)) = 7 (gsplat's 0.01 floor under the discriminant).
    let k = Intrinsics {
        width: 64,
        height: 48,
        fx: 100.0,
        fy: 100.0,
        cx: 32.0,
        cy: 24.0,
    };
    let camera = Camera::new(k, Quat::IDENTITY, Vec3::ZERO);
    let mut splats = Splats::empty(0, 1);
    let rotation = Quat::from_rotation_y(0.7) * 2.0;
    let (dc, raw_opacity, raw_label) = ([0.4, -0.2, -3.0], 0.3, -1.2);
    let log_scale = Vec3::splat(0.1f32.ln());
    splats.push(
        Vec3::new(0.0, 0.0, 5.0),
        log_scale,
        rotation,
        raw_opacity,
        &dc,
        &[raw_label],
        0,
        0,
    );
    let p = reference::project(&splats, &camera, &RenderSettings::default());
    let close = |a: f32, b: f32| (a - b).abs() <= 1e-6 * b.abs().max(1.0);
    assert_eq!(p.radii, [7]);
    assert!(close(p.means2d[0].x, 32.0) && close(p.means2d[0].y, 24.0));
    assert!(close(p.conics[0].x, 1.0 / 4.3) && close(p.conics[0].z, 1.0 / 4.3));
    assert!(p.conics[0].y.abs() < 1e-7);
    assert_eq!(p.depths, [5.0]);
    let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
    assert!(close(p.opacities[0], sigmoid(raw_opacity)));
    assert!(close(p.labels[0], sigmoid(raw_label)));
    // Colour max(SH_C0 · dc + 0.5, 0); the blue channel is clamped, so its bit is clear.
    assert!(close(p.colors[0].x, SH_C0 * 0.4 + 0.5) && close(p.colors[0].y, 0.5 - SH_C0 * 0.2));
    assert_eq!((p.colors[0].z, p.color_pass[0]), (0.0, 0b011));
}

#[test]
fn tiles_list_the_gaussians_whose_radius_rectangle_covers_them_by_depth_then_index() {
    let (mean, conic) = (glam::Vec2::new(10.0, 8.0), Vec3::new(0.1, 0.0, 0.1));
    let p = hand_made(&[
        (mean, conic, 3.0, 4, 0.5),
        (mean, conic, 1.0, 4, 0.5),
        (mean, conic, 3.0, 4, 0.5),
        // Reaches only the second tile column (x from 20 to 28).
        (glam::Vec2::new(24.0, 8.0), conic, 0.5, 4, 0.5),
        // Culled.
        (mean, conic, 0.1, 0, 0.5),
    ]);
    let tiles = reference::TileLists::new(&p, 40, 20);
    assert_eq!((tiles.tiles_x, tiles.tiles_y), (3, 2));
    assert_eq!(tiles.at_pixel(5, 5), [1, 0, 2]);
    assert_eq!(tiles.at_pixel(17, 5), [3]);
    assert!(tiles.at_pixel(5, 17).is_empty());
}

#[test]
fn a_gaussian_blends_nowhere_outside_its_radius_rectangle() {
    // Wide (σ = 10 px) but with radius 4: its rectangle covers tile column 0 only. At pixel 17
    // its alpha, 0.9 · exp(-0.5 · 7.5² / 100), would pass the threshold, yet gsplat (and the
    // fast path) never look at it there.
    let p = hand_made(&[(
        glam::Vec2::new(10.0, 8.0),
        Vec3::new(0.01, 0.0, 0.01),
        2.0,
        4,
        0.9,
    )]);
    let tiles = reference::TileLists::new(&p, 40, 20);
    let settings = RenderSettings::default();
    assert_eq!(
        reference::blend_pixel(&p, &tiles, 15, 8, &settings)
            .blended
            .len(),
        1
    );
    assert!(
        reference::blend_pixel(&p, &tiles, 17, 8, &settings)
            .blended
            .is_empty()
    );
}

#[test]
fn a_pixel_skips_faint_gaussians_and_stops_before_the_one_that_would_end_it() {
    let (mean, conic) = (glam::Vec2::new(4.5, 4.5), Vec3::new(0.5, 0.0, 0.5));
    let p = hand_made(&[
        // Front: alpha 1/300 < 1/255, skipped.
        (mean, conic, 1.0, 3, 1.0 / 300.0),
        // Alpha 0.99 (clamped from 0.995): T = 0.01 behind it.
        (mean, conic, 2.0, 3, 0.995),
        // Would take T to 0.01 · 0.01 = 1e-4 <= 1e-4: the pixel stops, this one unblended.
        (mean, conic, 3.0, 3, 0.99),
        (mean, conic, 4.0, 3, 0.5),
    ]);
    let tiles = reference::TileLists::new(&p, 16, 16);
    let settings = RenderSettings::default();
    let pixel = reference::blend_pixel(&p, &tiles, 4, 4, &settings);
    let blended: Vec<usize> = pixel.blended.iter().map(|b| b.gaussian).collect();
    assert_eq!(blended, [1]);
    assert!(pixel.stopped);
    assert_eq!(
        (pixel.blended[0].raw_alpha, pixel.blended[0].alpha),
        (0.995, 0.99)
    );
    assert_eq!(pixel.final_transmittance, 1.0 - 0.99f32);
    // With no threshold the faint one blends too.
    let no_threshold = RenderSettings {
        alpha_threshold: 0.0,
        ..settings
    };
    let pixel = reference::blend_pixel(&p, &tiles, 4, 4, &no_threshold);
    assert_eq!(
        pixel.blended.iter().map(|b| b.gaussian).collect::<Vec<_>>(),
        [0, 1]
    );
}
