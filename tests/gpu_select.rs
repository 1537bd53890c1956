//! The GPU selection pass against the CPU's rules: straight through it takes exactly the
//! Gaussians `splats::selection::hits` takes for every shape (rectangle, polygon, brush, sphere,
//! box; hidden and deleted never), and front-most it leaves out what `damage::pick::front_hits`
//! leaves out behind a wall. On lavapipe in CI.

mod gpu_support;

use glam::{Quat, Vec2, Vec3};

use damage_twin::damage::pick::front_hits;
use damage_twin::gpu::GpuRenderSettings;
use damage_twin::gpu::select::GpuSelector;
use damage_twin::raster::RenderSettings;
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use damage_twin::splats::model::state::{DELETED, HIDDEN};
use damage_twin::splats::selection::{Shape, hits};

fn shapes() -> Vec<Shape> {
    let star: Vec<Vec2> = (0..10)
        .map(|i| {
            let a = i as f32 * std::f32::consts::TAU / 10.0;
            let r = if i % 2 == 0 { 30.0 } else { 12.0 };
            Vec2::new(60.0 + r * a.cos(), 40.0 + r * a.sin())
        })
        .collect();
    vec![
        Shape::Rect {
            a: Vec2::new(90.0, 70.0),
            b: Vec2::new(20.5, 10.25),
        },
        Shape::Polygon(star),
        Shape::Brush {
            centres: vec![
                Vec2::new(30.0, 30.0),
                Vec2::new(45.0, 38.0),
                Vec2::new(70.0, 50.0),
            ],
            radius: 9.5,
        },
        Shape::Sphere {
            centre: Vec3::new(0.2, -0.1, 0.3),
            radius: 0.9,
        },
        Shape::Box {
            a: Vec3::new(0.5, 0.8, -1.0),
            b: Vec3::new(-1.2, -0.4, 1.5),
        },
    ]
}

#[test]
fn straight_through_matches_the_cpu_for_every_shape() {
    let mut splats = gpu_support::random_splats(4000, 0, 21);
    for g in (0..splats.len()).step_by(7) {
        splats.meta.state[g] |= HIDDEN;
    }
    for g in (3..splats.len()).step_by(11) {
        splats.meta.state[g] |= DELETED;
    }
    let camera = gpu_support::camera(120, 80);
    let ctx = gpu_support::context();
    let mut selector = GpuSelector::new(&ctx).unwrap();
    for shape in shapes() {
        let want = hits(&splats, &camera, &shape);
        let got = selector.hits(&splats, 1, &camera, &shape, None).unwrap();
        let count = want.iter().filter(|&&h| h).count();
        assert!(count > 20, "{shape:?} takes only {count}");
        let differ: Vec<usize> = (0..splats.len()).filter(|&g| got[g] != want[g]).collect();
        assert!(
            differ.is_empty(),
            "{shape:?}: GPU and CPU differ at {differ:?}"
        );
    }
}

/// A front wall at z = 0 and a back wall at z = 1 (9×9 Gaussians each), seen along +z.
fn two_walls() -> (Splats, Camera) {
    let mut splats = Splats::empty(0, 0);
    let mut id = 0;
    for (z, colour) in [(0.0, [1.0, 0.0, 0.0]), (1.0, [0.0, 0.0, 1.0])] {
        for x in -4..=4 {
            for y in -4..=4 {
                let mean = Vec3::new(x as f32 * 0.1, y as f32 * 0.1, z);
                let scale = Vec3::splat(0.08f32.ln());
                splats.push(mean, scale, Quat::IDENTITY, 6.0, &colour, &[], id, 0);
                id += 1;
            }
        }
    }
    let k = Intrinsics {
        width: 64,
        height: 48,
        fx: 60.0,
        fy: 60.0,
        cx: 32.0,
        cy: 24.0,
    };
    (
        splats,
        Camera::new(k, Quat::IDENTITY, Vec3::new(0.0, 0.0, 4.0)),
    )
}

#[test]
fn front_most_matches_the_cpu_and_sees_behind_a_hidden_wall() {
    let (mut splats, camera) = two_walls();
    // Corners off the Gaussians' exact pixel positions (every 1.5 px from 26): a centre on the
    // edge is a tie that rounding decides either way.
    let shape = Shape::Rect {
        a: Vec2::new(25.1, 17.1),
        b: Vec2::new(37.3, 29.3),
    };
    let cpu_settings = RenderSettings::new(Vec3::ZERO, 0);
    let gpu_settings = GpuRenderSettings::from(&cpu_settings);
    let ctx = gpu_support::context();
    let mut selector = GpuSelector::new(&ctx).unwrap();
    let got = selector
        .hits(&splats, 1, &camera, &shape, Some(&gpu_settings))
        .unwrap();
    assert_eq!(got, front_hits(&splats, &camera, &shape, &cpu_settings));
    assert!((0..81).filter(|&g| got[g]).count() >= 4);
    assert!(
        !(81..162).any(|g| got[g]),
        "the back wall is behind the front one"
    );
    for g in 0..81 {
        splats.meta.state[g] |= HIDDEN;
    }
    // A new key: the hidden wall no longer draws.
    let got = selector
        .hits(&splats, 2, &camera, &shape, Some(&gpu_settings))
        .unwrap();
    assert_eq!(got, front_hits(&splats, &camera, &shape, &cpu_settings));
    assert!((81..162).any(|g| got[g]) && !(0..81).any(|g| got[g]));
}
