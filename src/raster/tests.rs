//! Stage tests of the tile kernels alone (projection excluded): the blend backward's gradients
//! with respect to each Gaussian's 2D mean, conic, opacity, colour, depth and labels against
//! central differences of the forward blend and against the plain reference's per-pixel
//! backward, and the forward blend against the reference's per-pixel loop on edge tiles.

use glam::{Vec2, Vec3};

use super::bin::TileBins;
use super::forward::{rasterize, write_output};
use super::raster_backward::{rasterize_backward, unpack_screen_grads};
use super::segments::SegmentStore;
use super::{PixelGrads, Projected, RenderOutput, RenderSettings, ScreenGrads, reference};

const W: u32 = 40;
const H: u32 = 36;
const L: usize = 2;

fn scene(seed: u64, n: usize) -> Projected {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut u = |lo: f32, hi: f32| lo + (hi - lo) * rng.f32();
    let mut p = Projected::default();
    for _ in 0..n {
        let sx = u(2.0, 7.0);
        let sy = u(2.0, 7.0);
        let rho = u(-0.6, 0.6);
        let cov = Vec3::new(sx * sx, rho * sx * sy, sy * sy);
        let det = cov.x * cov.z - cov.y * cov.y;
        let conic = Vec3::new(cov.z / det, -cov.y / det, cov.x / det);
        let opacity = u(0.2, 0.9);
        p.means2d
            .push(Vec2::new(u(0.0, W as f32), u(0.0, H as f32)));
        p.conics.push(conic);
        p.depths.push(u(1.0, 5.0));
        p.radii.push((3.0 * sx.max(sy) * 1.3).ceil() as u32);
        p.colors
            .push(Vec3::new(u(0.0, 1.0), u(0.0, 1.0), u(0.0, 1.0)));
        p.opacities.push(opacity);
        p.labels.extend([u(0.0, 1.0), u(0.0, 1.0)]);
        // No alpha threshold (see `settings`): the extent box is unbounded.
        p.extents.push(Vec2::splat(f32::INFINITY));
    }
    p
}

struct Weights {
    color: Vec<f32>,
    alpha: Vec<f32>,
    depth: Vec<f32>,
    labels: Vec<f32>,
}

fn weights(seed: u64) -> Weights {
    let mut rng = fastrand::Rng::with_seed(seed);
    let px = (W * H) as usize;
    let mut v = |n: usize| (0..n).map(|_| 2.0 * rng.f32() - 1.0).collect();
    Weights {
        color: v(px * 3),
        alpha: v(px),
        depth: v(px),
        labels: v(px * L),
    }
}

/// The 1/255 skip is a real discontinuity: a central difference whose step moves one pixel
/// across it jumps by ~alpha/(2 eps). Differences are taken with the skip off.
fn settings() -> RenderSettings {
    RenderSettings {
        background: Vec3::new(0.3, 0.1, 0.7),
        alpha_threshold: 0.0,
        ..Default::default()
    }
}

fn render(p: &Projected) -> (RenderOutput, TileBins, Vec<f32>, SegmentStore) {
    let mut bins = TileBins::default();
    bins.build(p, W, H);
    let (mut state, mut segments) = (Vec::new(), SegmentStore::default());
    rasterize(p, &bins, L, &settings(), &mut state, &mut segments);
    let mut out = RenderOutput::default();
    write_output(&state, &bins, L, settings().background, W, H, &mut out);
    (out, bins, state, segments)
}

fn loss(p: &Projected, w: &Weights) -> f64 {
    let (out, ..) = render(p);
    let dot =
        |a: &[f32], b: &[f32]| -> f64 { a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum() };
    dot(&out.color, &w.color)
        + dot(&out.alpha, &w.alpha)
        + dot(&out.depth, &w.depth)
        + dot(&out.labels, &w.labels)
}

fn screen_grads(p: &Projected, w: &Weights) -> ScreenGrads {
    let (_, bins, state, segments) = render(p);
    let v = PixelGrads {
        color: &w.color,
        alpha: Some(&w.alpha),
        depth: Some(&w.depth),
        labels: Some(&w.labels),
    };
    let (mut isect, mut gauss) = (Vec::new(), Vec::new());
    rasterize_backward(
        p,
        &bins,
        &state,
        &segments,
        L,
        &settings(),
        &v,
        W,
        H,
        &mut isect,
        &mut gauss,
    );
    let mut screen = ScreenGrads::default();
    unpack_screen_grads(&gauss, p.radii.len(), L, &mut screen);
    screen
}

type Getter = fn(&mut Projected, usize) -> &mut f32;
type Reader = fn(&ScreenGrads, usize) -> f32;

#[test]
fn blend_backward_matches_finite_differences_in_screen_space() {
    let lanes: [(&str, Getter, Reader, f32); 11] = [
        (
            "mean.x",
            |p, g| &mut p.means2d[g].x,
            |s, g| s.v_means2d[g].x,
            1e-3,
        ),
        (
            "mean.y",
            |p, g| &mut p.means2d[g].y,
            |s, g| s.v_means2d[g].y,
            1e-3,
        ),
        (
            "conic.a",
            |p, g| &mut p.conics[g].x,
            |s, g| s.v_conics[g].x,
            1e-4,
        ),
        (
            "conic.b",
            |p, g| &mut p.conics[g].y,
            |s, g| s.v_conics[g].y,
            1e-4,
        ),
        (
            "conic.c",
            |p, g| &mut p.conics[g].z,
            |s, g| s.v_conics[g].z,
            1e-4,
        ),
        (
            "opacity",
            |p, g| &mut p.opacities[g],
            |s, g| s.v_opacities[g],
            1e-4,
        ),
        (
            "red",
            |p, g| &mut p.colors[g].x,
            |s, g| s.v_colors[g].x,
            1e-2,
        ),
        (
            "blue",
            |p, g| &mut p.colors[g].z,
            |s, g| s.v_colors[g].z,
            1e-2,
        ),
        ("depth", |p, g| &mut p.depths[g], |s, g| s.v_depths[g], 1e-2),
        (
            "label0",
            |p, g| &mut p.labels[g * L],
            |s, g| s.v_labels[g * L],
            1e-2,
        ),
        (
            "label1",
            |p, g| &mut p.labels[g * L + 1],
            |s, g| s.v_labels[g * L + 1],
            1e-2,
        ),
    ];
    let mut bad = Vec::new();
    for seed in 0..3 {
        let p = scene(seed, 7);
        let w = weights(seed + 50);
        let s = screen_grads(&p, &w);
        for g in 0..p.radii.len() {
            for (name, get, grad, eps) in &lanes {
                let analytic = grad(&s, g) as f64;
                let mut q = p.clone();
                let x = *get(&mut q, g);
                *get(&mut q, g) = x + eps;
                let lp = loss(&q, &w);
                *get(&mut q, g) = x - eps;
                let lm = loss(&q, &w);
                let fd = (lp - lm) / (2.0 * *eps as f64);
                let ok = (fd - analytic).abs() <= 0.02 * fd.abs().max(analytic.abs()) + 2e-3;
                if !ok {
                    bad.push(format!(
                        "seed {seed} g{g} {name}: analytic {analytic:.5e} fd {fd:.5e}"
                    ));
                }
            }
        }
    }
    for b in &bad {
        eprintln!("{b}");
    }
    assert!(bad.len() <= 2, "{} screen-space lanes disagree", bad.len());
}

/// The tiled forward against the plain reference's per-pixel loop (`reference::blend`) on an
/// image whose right and bottom tiles reach past its edge, with Gaussians centred beyond it,
/// dense enough that many pixels stop early, and the 1/255 skip on: what the opacity-aware tile
/// rectangles, the segment masks, the live-segment skip and the edge clipping leave out must be
/// exactly what the per-pixel loop never blends.
#[test]
fn forward_matches_a_per_pixel_loop_on_edge_tiles() {
    let s = RenderSettings {
        background: Vec3::new(0.3, 0.1, 0.7),
        ..Default::default()
    };
    let mut worst = 0.0f32;
    let mut stopped = 0;
    for seed in 0..4 {
        let mut p = scene(seed + 100, 200);
        let mut rng = fastrand::Rng::with_seed(seed);
        for g in 0..p.radii.len() {
            // Spread the means over [-8, W + 12) × [-8, H + 12): some past the right and bottom.
            p.means2d[g] = Vec2::new(
                rng.f32() * (W as f32 + 20.0) - 8.0,
                rng.f32() * (H as f32 + 20.0) - 8.0,
            );
            p.opacities[g] = 0.6 + 0.39 * rng.f32();
            // The opacity-aware box the fast path bins by (`Projected::extents`), as projection
            // would compute it for this opacity and the default threshold.
            let cov = p.conics[g].x * p.conics[g].z - p.conics[g].y * p.conics[g].y;
            let (var_x, var_y) = (p.conics[g].z / cov, p.conics[g].x / cov);
            let power_max = (p.opacities[g] / s.alpha_threshold).ln() + 1e-3;
            p.extents[g] = Vec2::new(
                (2.0 * power_max * var_x).sqrt() * 1.001 + 0.01,
                (2.0 * power_max * var_y).sqrt() * 1.001 + 0.01,
            );
        }
        let mut bins = TileBins::default();
        bins.build(&p, W, H);
        let (mut state, mut segments) = (Vec::new(), SegmentStore::default());
        rasterize(&p, &bins, L, &s, &mut state, &mut segments);
        let mut out = RenderOutput::default();
        write_output(&state, &bins, L, s.background, W, H, &mut out);
        let want = reference::blend(&p, L, W, H, &s);
        for (got, want) in [
            (&out.color, &want.color),
            (&out.alpha, &want.alpha),
            (&out.depth, &want.depth),
            (&out.labels, &want.labels),
        ] {
            for (a, b) in got.iter().zip(want) {
                worst = worst.max((a - b).abs());
            }
        }
        let tiles = reference::TileLists::new(&p, W, H);
        for y in 0..H {
            for x in 0..W {
                stopped += reference::blend_pixel(&p, &tiles, x, y, &s).stopped as usize;
            }
        }
    }
    // Measured: 9.5e-7 (on depths up to 5). The fast path's `exp` is within 2 ulp of the
    // standard library's; a pixel where the two decided the skip or the stop differently would
    // differ by over 1e-3.
    assert!(worst < 5e-6, "largest difference {worst}");
    // The scenes must exercise the early stop, or this test would not cover it (measured: 1383
    // of the 4 × 1440 pixels).
    eprintln!("largest difference {worst}, {stopped} pixels stopped early");
    assert!(
        stopped > (W * H / 2) as usize,
        "only {stopped} pixels stopped early"
    );
}

/// The tile kernels' screen-space gradients against the reference's per-pixel backward
/// (`reference::blend_backward`) on the same projected frames, with the 1/255 skip on and the
/// fast path's opacity-aware boxes unbounded (the stage is compared alone: projection and its
/// extents are the full rasterizer's test, `tests/raster_reference.rs`).
#[test]
fn blend_backward_matches_the_reference_in_screen_space() {
    let s = RenderSettings {
        alpha_threshold: super::ALPHA_THRESHOLD,
        ..settings()
    };
    let mut worst = 0.0f32;
    for seed in 0..3 {
        let p = scene(seed + 200, 60);
        let w = weights(seed + 60);
        let v = PixelGrads {
            color: &w.color,
            alpha: Some(&w.alpha),
            depth: Some(&w.depth),
            labels: Some(&w.labels),
        };
        let mut bins = TileBins::default();
        bins.build(&p, W, H);
        let (mut state, mut segments) = (Vec::new(), SegmentStore::default());
        rasterize(&p, &bins, L, &s, &mut state, &mut segments);
        let (mut isect, mut gauss) = (Vec::new(), Vec::new());
        rasterize_backward(
            &p, &bins, &state, &segments, L, &s, &v, W, H, &mut isect, &mut gauss,
        );
        let mut got = ScreenGrads::default();
        unpack_screen_grads(&gauss, p.radii.len(), L, &mut got);
        let want = reference::blend_backward(&p, L, W, H, &s, &v);
        let flat2 = |v: &[Vec2]| v.iter().flat_map(|m| [m.x, m.y]).collect::<Vec<f32>>();
        let flat3 = |v: &[Vec3]| v.iter().flat_map(|m| [m.x, m.y, m.z]).collect::<Vec<f32>>();
        for (got, want) in [
            (flat2(&got.v_means2d), flat2(&want.v_means2d)),
            (flat3(&got.v_conics), flat3(&want.v_conics)),
            (flat3(&got.v_colors), flat3(&want.v_colors)),
            (got.v_opacities.clone(), want.v_opacities.clone()),
            (got.v_depths.clone(), want.v_depths.clone()),
            (got.v_labels.clone(), want.v_labels.clone()),
        ] {
            // Relative to the tensor's largest magnitude: per-Gaussian sums over hundreds of
            // pixels, in f32 in tile order against f64.
            let scale = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            for (a, b) in got.iter().zip(&want) {
                let e = (a - b).abs() / scale;
                if !(e <= worst) {
                    worst = e;
                }
            }
        }
    }
    // Measured: 8.4e-7 (AVX-512 and AVX2 builds), 9.2e-7 (baseline build).
    eprintln!("largest error relative to the tensor's scale {worst:.3e}");
    assert!(worst < 5e-6, "largest scaled error {worst}");
}
