//! Where a scene is, derived from its survey cameras (and points when present): the point the
//! cameras look at, a radius, the world up and the ground height, for the initial view, the grid
//! and the frustum size. Pure geometry; no rendering.

use glam::{Mat3, Vec3};

use crate::app::camera_controller::{CameraController, OrbitPose, estimate_up};
use crate::scene::Camera;

/// A scene's extent as the viewer uses it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneFrame {
    pub up: Vec3,
    /// Point closest (least squares) to every camera's optical axis, i.e. what the survey looked at.
    pub centre: Vec3,
    /// Median distance from the cameras to the centre.
    pub camera_distance: f32,
    /// Height (along `up`) of the ground plane for the grid.
    pub ground: f32,
}

impl SceneFrame {
    /// Frame of a set of survey cameras and optional scene points.
    pub fn from_cameras(cameras: &[Camera], points: &[Vec3]) -> SceneFrame {
        let up = estimate_up(cameras);
        let centre = look_at_point(cameras)
            .or_else(|| mean(points))
            .or_else(|| mean(&cameras.iter().map(Camera::position).collect::<Vec<_>>()))
            .unwrap_or(Vec3::ZERO);
        let mut distances: Vec<f32> = cameras
            .iter()
            .map(|c| (c.position() - centre).length())
            .filter(|d| d.is_finite())
            .collect();
        distances.sort_by(f32::total_cmp);
        let camera_distance = distances
            .get(distances.len() / 2)
            .copied()
            .filter(|d| *d > 1e-6)
            .unwrap_or(1.0);
        // Ground: a low percentile of the points' height (robust to a few floaters below), or a
        // camera distance below the centre when there are no points.
        let mut heights: Vec<f32> = points
            .iter()
            .map(|p| p.dot(up))
            .filter(|h| h.is_finite())
            .collect();
        heights.sort_by(f32::total_cmp);
        let ground = heights
            .get(heights.len() / 50)
            .copied()
            .unwrap_or(centre.dot(up) - 0.5 * camera_distance);
        SceneFrame {
            up,
            centre,
            camera_distance,
            ground,
        }
    }

    /// The initial viewer camera: looking at the centre from about the survey's distance.
    pub fn controller(&self) -> CameraController {
        let mut c = CameraController::new(
            self.up,
            OrbitPose {
                target: self.centre,
                distance: self.camera_distance,
                yaw: 0.8,
                pitch: 0.45,
            },
        );
        c.fly_speed = self.camera_distance * 0.5;
        c
    }

    /// Grid spacing: a power of ten about a tenth of the camera distance.
    pub fn grid_spacing(&self) -> f32 {
        let raw = (self.camera_distance * 0.1).max(1e-6);
        10f32.powf(raw.log10().round())
    }
}

fn mean(points: &[Vec3]) -> Option<Vec3> {
    if points.is_empty() {
        return None;
    }
    let m = points.iter().copied().sum::<Vec3>() / points.len() as f32;
    m.is_finite().then_some(m)
}

/// Least-squares point nearest to every optical axis: Σ(I − d dᵀ) x = Σ(I − d dᵀ) c. `None` when
/// the axes are (nearly) parallel, e.g. a single camera or a straight fly-past.
fn look_at_point(cameras: &[Camera]) -> Option<Vec3> {
    if cameras.len() < 2 {
        return None;
    }
    let mut a = Mat3::ZERO;
    let mut b = Vec3::ZERO;
    for c in cameras {
        let d = (c.rotation.inverse() * Vec3::Z).normalize_or_zero();
        let p = Mat3::IDENTITY - outer(d, d);
        a += p;
        b += p * c.position();
    }
    // A well-conditioned system needs axes in at least two directions.
    if !(a.determinant().abs() > 1e-3 * (cameras.len() as f32).powi(3)) {
        return None;
    }
    let x = a.inverse() * b;
    x.is_finite().then_some(x)
}

fn outer(u: Vec3, v: Vec3) -> Mat3 {
    Mat3::from_cols(u * v.x, u * v.y, u * v.z)
}
