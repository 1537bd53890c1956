//! The tiny scene the training-loop tests train on: 60 opaque coloured blobs in a unit cube,
//! photographed by 12 cameras around it (and one held-out view), and a random initial model.
#![allow(dead_code)]

use glam::{Quat, Vec3};

use damage_twin::raster::{RenderSettings, render};
use damage_twin::scene::{Camera, Intrinsics, Mask, RgbImage};
use damage_twin::splats::Splats;
use damage_twin::splats::init::{InitOptions, from_points, random_points};
use damage_twin::train::spec::TrainView;

pub const SIZE: u32 = 48;

/// 60 opaque coloured blobs in a unit cube: the scene the cameras photograph.
pub fn ground_truth() -> Splats {
    let mut rng = fastrand::Rng::with_seed(7);
    let mut s = Splats::empty(0, 0);
    for id in 0..60 {
        let mean = Vec3::new(rng.f32(), rng.f32(), rng.f32()) - 0.5;
        let colour = [rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5].map(|c| c * 3.0);
        s.push(
            mean,
            Vec3::splat((0.06 + 0.08 * rng.f32()).ln()),
            Quat::IDENTITY,
            2.0,
            &colour,
            &[],
            id,
            0,
        );
    }
    s
}

pub fn camera(angle: f32, height: f32) -> Camera {
    let k = Intrinsics {
        width: SIZE,
        height: SIZE,
        fx: 50.0,
        fy: 50.0,
        cx: SIZE as f32 / 2.0,
        cy: SIZE as f32 / 2.0,
    };
    let eye = Vec3::new(3.0 * angle.cos(), height, 3.0 * angle.sin());
    Camera::look_at(k, eye, Vec3::ZERO, Vec3::Y)
}

pub fn view(truth: &Splats, name: &str, camera: Camera) -> TrainView {
    let out = render(truth, &camera, &RenderSettings::new(Vec3::ZERO, 0));
    TrainView {
        name: name.into(),
        camera,
        image: RgbImage {
            width: SIZE,
            height: SIZE,
            data: out.color,
        },
        labels: Vec::new(),
        region: None,
        light: None,
    }
}

pub fn scene() -> (Vec<TrainView>, Vec<TrainView>) {
    let truth = ground_truth();
    let train = (0..12)
        .map(|i| {
            let a = i as f32 * std::f32::consts::TAU / 12.0;
            view(
                &truth,
                &format!("train{i}"),
                camera(a, if i % 2 == 0 { 0.8 } else { -0.5 }),
            )
        })
        .collect();
    let test = vec![view(&truth, "test", camera(0.26, 0.2))];
    (train, test)
}

pub fn initial() -> Splats {
    initial_with_labels(0)
}

/// The random initial model with `label_channels` damage channels.
pub fn initial_with_labels(label_channels: usize) -> Splats {
    let points = random_points(300, 0.6, 3);
    from_points(
        &points.0,
        &points.1,
        &InitOptions {
            sh_degree: 1,
            label_channels,
            ..InitOptions::default()
        },
    )
    .unwrap()
}

/// The blob scene's views, each with one label mask: a square off centre, different per view,
/// so the label loss pulls on the geometry as inconsistent masks would.
pub fn labelled_views() -> Vec<TrainView> {
    let (mut views, _) = scene();
    for (i, view) in views.iter_mut().enumerate() {
        let (x0, y0) = (8 + 2 * i as u32, 12 + i as u32);
        let mut mask = Mask::empty(SIZE, SIZE);
        for y in y0..y0 + 14 {
            for x in x0..x0 + 10 {
                mask.data[(y * SIZE + x) as usize] = 1;
            }
        }
        view.labels = vec![mask];
    }
    views
}

/// The largest absolute difference between two equally long parameter arrays.
pub fn max_gap(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f32::max)
}
