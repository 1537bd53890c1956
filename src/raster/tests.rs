//! Stage tests of the blend backward in screen space: the gradients with respect to each
//! Gaussian's 2D mean, conic, opacity, colour, depth and labels against central differences of
//! the forward blend alone (projection excluded, so any error is the tile kernels').

use glam::{Vec2, Vec3};

use super::bin::TileBins;
use super::forward::{rasterize, write_output};
use super::raster_backward::{rasterize_backward, unpack_screen_grads};
use super::segments::SegmentStore;
use super::{PixelGrads, Projected, RenderOutput, RenderSettings, ScreenGrads};

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

/// gsplat's per-pixel loop, one pixel at a time with the standard library's `exp`: every
/// Gaussian in depth order, the `sigma < 0 || alpha < threshold` skip, the exclusive
/// `next_T <= 1e-4` stop.
fn brute_force_color(p: &Projected, s: &RenderSettings, x: u32, y: u32) -> (Vec3, f32) {
    let mut order: Vec<usize> = (0..p.radii.len()).collect();
    order.sort_by(|&i, &j| p.depths[i].total_cmp(&p.depths[j]).then(i.cmp(&j)));
    let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
    let (mut color, mut t) = (Vec3::ZERO, 1.0f32);
    for g in order {
        let d = p.means2d[g] - centre;
        let k = p.conics[g];
        let sigma = 0.5 * (k.x * d.x * d.x + k.z * d.y * d.y) + k.y * d.x * d.y;
        let alpha = (p.opacities[g] * (-sigma).exp()).min(s.alpha_max);
        if sigma < 0.0 || alpha < s.alpha_threshold {
            continue;
        }
        let next_t = t * (1.0 - alpha);
        if next_t <= super::TRANSMITTANCE_MIN {
            break;
        }
        color += p.colors[g] * alpha * t;
        t = next_t;
    }
    (color + t * s.background, t)
}

/// The tiled forward against [`brute_force_color`] on an image whose right and bottom tiles
/// reach past its edge, with Gaussians centred beyond it, dense enough that most pixels stop
/// early, and the 1/255 skip on: what the segment masks, the live-segment skip and the edge
/// clipping leave out must be exactly what the per-pixel loop never blends.
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
        }
        let mut bins = TileBins::default();
        bins.build(&p, W, H);
        let (mut state, mut segments) = (Vec::new(), SegmentStore::default());
        rasterize(&p, &bins, L, &s, &mut state, &mut segments);
        let mut out = RenderOutput::default();
        write_output(&state, &bins, L, s.background, W, H, &mut out);
        for y in 0..H {
            for x in 0..W {
                let (want, t) = brute_force_color(&p, &s, x, y);
                let i = (y * W + x) as usize;
                let got = Vec3::from_slice(&out.color[i * 3..i * 3 + 3]);
                worst = worst.max((got - want).abs().max_element());
                worst = worst.max((out.alpha[i] - (1.0 - t)).abs());
                stopped += (t < 0.01) as usize;
            }
        }
    }
    assert!(worst < 1e-4, "largest difference {worst}");
    // The scenes must exercise the early stop, or this test would not cover it.
    assert!(stopped > (W * H) as usize, "only {stopped} opaque pixels");
}
