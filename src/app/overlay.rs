//! Grid and survey-camera frusta as 3D line segments, clipped at the near plane and projected
//! through the viewport camera into screen points for egui's painter; and frustum picking (which
//! camera a click hits). Geometry only: the viewport does the drawing.

use glam::{Vec2, Vec3};

use crate::app::scene_frame::SceneFrame;
use crate::scene::Camera;

/// Near plane for clipping, relative to the scene's camera distance.
const NEAR_FRACTION: f32 = 1e-3;

/// A world-space segment with a colour class.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    pub a: Vec3,
    pub b: Vec3,
    pub kind: SegmentKind,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SegmentKind {
    Grid,
    GridAxis,
    Frustum,
    FrustumSelected,
}

/// Grid lines on the ground plane around the scene centre.
pub fn grid(frame: &SceneFrame, half_lines: i32) -> Vec<Segment> {
    let up = frame.up;
    let helper = if up.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    let e1 = (helper - up * helper.dot(up)).normalize();
    let e2 = up.cross(e1);
    let spacing = frame.grid_spacing();
    // Snap the origin to the grid so lines do not swim when the centre moves.
    let c = frame.centre - up * frame.centre.dot(up);
    let origin = e1 * (c.dot(e1) / spacing).round() * spacing
        + e2 * (c.dot(e2) / spacing).round() * spacing
        + up * frame.ground;
    let extent = half_lines as f32 * spacing;
    let mut out = Vec::with_capacity(4 * half_lines as usize + 2);
    for i in -half_lines..=half_lines {
        let o = i as f32 * spacing;
        let kind = if i == 0 {
            SegmentKind::GridAxis
        } else {
            SegmentKind::Grid
        };
        out.push(Segment {
            a: origin + e1 * o - e2 * extent,
            b: origin + e1 * o + e2 * extent,
            kind,
        });
        out.push(Segment {
            a: origin + e2 * o - e1 * extent,
            b: origin + e2 * o + e1 * extent,
            kind,
        });
    }
    out
}

/// The four image corners of a survey camera at `depth` in front of it, in world coordinates
/// (top-left, top-right, bottom-right, bottom-left).
pub fn frustum_corners(camera: &Camera, depth: f32) -> [Vec3; 4] {
    let k = &camera.intrinsics;
    let to_world = camera.rotation.inverse();
    let corner = |u: f32, v: f32| {
        let p_cam = Vec3::new((u - k.cx) / k.fx * depth, (v - k.cy) / k.fy * depth, depth);
        to_world * (p_cam - camera.translation)
    };
    let (w, h) = (k.width as f32, k.height as f32);
    [
        corner(0.0, 0.0),
        corner(w, 0.0),
        corner(w, h),
        corner(0.0, h),
    ]
}

/// Eight edges per camera (apex to corners, and the image rectangle).
pub fn frusta(cameras: &[Camera], depth: f32, selected: Option<usize>) -> Vec<Segment> {
    let mut out = Vec::with_capacity(cameras.len() * 8);
    for (i, camera) in cameras.iter().enumerate() {
        let kind = if selected == Some(i) {
            SegmentKind::FrustumSelected
        } else {
            SegmentKind::Frustum
        };
        let apex = camera.position();
        let c = frustum_corners(camera, depth);
        for j in 0..4 {
            out.push(Segment {
                a: apex,
                b: c[j],
                kind,
            });
            out.push(Segment {
                a: c[j],
                b: c[(j + 1) % 4],
                kind,
            });
        }
    }
    out
}

/// Projects a segment into pixel coordinates of `view`, clipped to the near plane; `None` when
/// it lies entirely behind it.
pub fn project_segment(view: &Camera, seg: &Segment, near: f32) -> Option<(Vec2, Vec2)> {
    let mut a = view.world_to_camera(seg.a);
    let mut b = view.world_to_camera(seg.b);
    // `!(z > near)` treats NaN as behind the camera.
    let a_in = a.z > near;
    let b_in = b.z > near;
    if !a_in && !b_in {
        return None;
    }
    if !a_in || !b_in {
        let t = (near - a.z) / (b.z - a.z);
        let p = a + (b - a) * t;
        if a_in {
            b = p;
        } else {
            a = p;
        }
    }
    let k = &view.intrinsics;
    let to_px = |p: Vec3| Vec2::new(k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy);
    let (pa, pb) = (to_px(a), to_px(b));
    (pa.is_finite() && pb.is_finite()).then_some((pa, pb))
}

/// Near-plane distance for a scene.
pub fn near_plane(frame: &SceneFrame) -> f32 {
    (frame.camera_distance * NEAR_FRACTION).max(1e-5)
}

/// Which survey camera a click at pixel `click` hits: the nearest camera whose projected image
/// rectangle contains the click, or whose apex is within `apex_radius` pixels.
pub fn pick_frustum(
    view: &Camera,
    cameras: &[Camera],
    depth: f32,
    near: f32,
    click: Vec2,
    apex_radius: f32,
) -> Option<usize> {
    let mut best: Option<(usize, f32)> = None;
    for (i, camera) in cameras.iter().enumerate() {
        let apex_cam = view.world_to_camera(camera.position());
        if !(apex_cam.z > near) {
            continue;
        }
        let corners = frustum_corners(camera, depth);
        let projected: Option<Vec<Vec2>> = corners
            .iter()
            .map(|&c| {
                let p = view.world_to_camera(c);
                (p.z > near).then(|| view.project(c)).flatten()
            })
            .collect();
        let inside = projected.is_some_and(|q| point_in_polygon(click, &q));
        let near_apex = view
            .project(camera.position())
            .is_some_and(|p| (p - click).length() <= apex_radius);
        if (inside || near_apex) && best.is_none_or(|(_, z)| apex_cam.z < z) {
            best = Some((i, apex_cam.z));
        }
    }
    best.map(|(i, _)| i)
}

/// Even-odd rule.
fn point_in_polygon(p: Vec2, poly: &[Vec2]) -> bool {
    let mut inside = false;
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + n - 1) % n]);
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
    }
    inside
}
