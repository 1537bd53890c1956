//! Drone paths: per survey, orbits around the building at two heights plus facade passes in
//! front of the most damaged walls, with seeded jitter, as COLMAP-convention cameras.
//! Survey 2 flies its own path (different radius, height and angles); both share the world frame.

use glam::Vec3;

use super::building::Building;
use crate::scene::{Camera, Intrinsics};

/// Pinhole intrinsics for a horizontal field of view.
pub fn intrinsics(width: u32, height: u32, hfov_degrees: f32) -> Intrinsics {
    let f = 0.5 * width as f32 / (0.5 * hfov_degrees.to_radians()).tan();
    Intrinsics {
        width,
        height,
        fx: f,
        fy: f,
        cx: 0.5 * width as f32,
        cy: 0.5 * height as f32,
    }
}

/// The cameras of survey `survey` (1 or 2), `views` of them, in flight order.
pub fn survey_path(
    building: &Building,
    survey: u32,
    views: usize,
    k: Intrinsics,
    seed: u64,
) -> Vec<Camera> {
    let mut rng = fastrand::Rng::with_seed(seed ^ (0xD20E_0000 + survey as u64));
    let spec = &building.spec;
    // The frame's extent (props excluded): orbits are ellipses a fixed distance off each facade.
    let size = Vec3::new(
        spec.bays_x as f32 * spec.bay_width,
        spec.bays_y as f32 * spec.bay_depth,
        spec.floors as f32 * spec.storey,
    );
    let c = 0.5 * size;
    let facade_views = if views >= 3 {
        (views * 4 / 15).max(1)
    } else {
        views
    };
    let orbit_views = views - facade_views;
    let (rings, facade_distance) = if survey <= 1 {
        let low = orbit_views * 11 / 20;
        (
            vec![(low, 9.5, 3.5, 0.0), (orbit_views - low, 12.0, 12.5, 0.5)],
            8.5,
        )
    } else {
        (vec![(orbit_views, 11.0, 7.5, 0.25)], 10.5)
    };
    let mut cams = Vec::with_capacity(views);
    // Facade passes first, so a short path (tests) still sees the damaged front.
    let front = building.facades[0].offset;
    let left = building.facades[3].offset;
    let n_front = facade_views - facade_views / 3;
    for i in 0..facade_views {
        let (along, count, idx) = if i < n_front {
            (0, n_front, i)
        } else {
            (1, facade_views - n_front, i - n_front)
        };
        let t = (idx as f32 + 0.5) / count as f32;
        let heights = if survey <= 1 { [2.4, 5.6] } else { [4.0, 4.0] };
        let z = heights[idx % 2] + rng.f32() * 0.6;
        let (eye, target) = if along == 0 {
            let x = 1.0 + t * (size.x - 2.0);
            let eye = Vec3::new(x, front - facade_distance - rng.f32(), z);
            let target = Vec3::new(
                x + (rng.f32() - 0.5) * 3.0 + (c.x - x) * 0.15,
                front,
                z - 0.4,
            );
            (eye, target)
        } else {
            let y = 1.0 + t * (size.y - 2.0);
            let eye = Vec3::new(left - facade_distance - rng.f32(), y, z);
            let target = Vec3::new(left, y + (c.y - y) * 0.2, z - 0.4);
            (eye, target)
        };
        cams.push(Camera::look_at(k, eye, target, Vec3::Z));
    }
    for (n, distance, height, phase) in rings {
        for i in 0..n {
            let angle = (i as f32 + phase) / n as f32 * std::f32::consts::TAU - 1.3;
            let jitter = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5);
            let eye = Vec3::new(
                c.x + (0.5 * size.x + distance) * angle.cos(),
                c.y + (0.5 * size.y + distance) * angle.sin(),
                height,
            ) + jitter * 0.8;
            let target = Vec3::new(c.x, c.y, 0.35 * size.z) + jitter * 1.5;
            cams.push(Camera::look_at(k, eye, target, Vec3::Z));
        }
    }
    cams
}

/// The cameras of a bridge survey (`bridge::bridge` with `spans` spans), `views` of them, in
/// flight order: strips along the front side at two heights (pier columns, then girders), a
/// strip under the deck on the centre line looking up and ahead at the girders' inner faces, the
/// soffit and the pier caps, then the back side at two heights. Survey 2 flies farther out and at
/// other heights. A fifth of the views fly under the deck.
pub fn bridge_path(spans: u32, survey: u32, views: usize, k: Intrinsics, seed: u64) -> Vec<Camera> {
    use super::bridge::{SIDE_PLANE, length};
    let mut rng = fastrand::Rng::with_seed(seed ^ (0xB20E_0000 + survey as u64));
    let len = length(spans);
    let first = survey <= 1;
    let under = views / 5;
    let sides = views - under;
    let (distance, heights) = if first {
        (9.0, [(3.4, 4.4), (6.6, 6.2)])
    } else {
        (10.5, [(4.0, 4.6), (7.4, 6.4)])
    };
    // (side, eye height, target height) per pass, in flight order.
    let passes = [
        (-1.0, heights[0]),
        (-1.0, heights[1]),
        (1.0, heights[1]),
        (1.0, heights[0]),
    ];
    let along = |i: usize, n: usize, margin: f32| {
        -margin + (i as f32 + 0.5) / n as f32 * (len + 2.0 * margin)
    };
    let mut cams = Vec::with_capacity(views);
    for (p, &(side, (z_eye, z_target))) in passes.iter().enumerate() {
        let n = sides / 4 + usize::from(p < sides % 4);
        if p == 2 {
            push_under_strip(&mut cams, &mut rng, under, len, first, k);
        }
        for i in 0..n {
            let x = along(i, n, 2.0);
            let eye = Vec3::new(
                x,
                side * (SIDE_PLANE + distance + rng.f32()),
                z_eye + 0.5 * rng.f32(),
            );
            let target = Vec3::new(
                x + (rng.f32() - 0.5) * 5.0,
                side * SIDE_PLANE,
                z_target + (rng.f32() - 0.5) * 0.6,
            );
            cams.push(Camera::look_at(k, eye, target, Vec3::Z));
        }
    }
    cams
}

fn push_under_strip(
    cams: &mut Vec<Camera>,
    rng: &mut fastrand::Rng,
    n: usize,
    len: f32,
    first: bool,
    k: Intrinsics,
) {
    use super::bridge::{CLEARANCE, girder_bottom};
    let z_eye = if first { 3.2 } else { 3.6 };
    for i in 0..n {
        let x = (i as f32 + 0.5) / n as f32 * len;
        let ahead = if i % 2 == 0 { 5.0 } else { -5.0 };
        let eye = Vec3::new(x, (rng.f32() - 0.5) * 0.8, z_eye + 0.4 * rng.f32());
        let target = Vec3::new(
            x + ahead,
            if (i / 2) % 2 == 0 { 2.2 } else { -2.2 },
            0.5 * (girder_bottom() + CLEARANCE),
        );
        cams.push(Camera::look_at(k, eye, target, Vec3::Z));
    }
}
