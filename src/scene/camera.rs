//! A pinhole camera in COLMAP's convention: looks along +z, x right, y down; the pose is
//! world-to-camera `R, t` (`x_cam = R · x_world + t`). Intrinsics are in pixels of the image as
//! stored; every distorted model is undistorted to this on load, so the renderer sees only pinholes.

use glam::{Mat3, Quat, Vec3};
use serde::{Deserialize, Serialize};

/// Pinhole intrinsics in pixels of an image `width × height`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

impl Intrinsics {
    /// Intrinsics for the same lens at another image size. Every value scales with the image
    /// (DESIGN.md: downscaling by s scales fx, fy, cx, cy by 1/s), per axis so that a target width
    /// with a rounded height stays exact.
    pub fn resized(&self, width: u32, height: u32) -> Intrinsics {
        let sx = width as f32 / self.width as f32;
        let sy = height as f32 / self.height as f32;
        Intrinsics {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: self.cx * sx,
            cy: self.cy * sy,
        }
    }
}

/// A posed pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub intrinsics: Intrinsics,
    /// World-to-camera rotation (unit quaternion; COLMAP's `qvec`).
    pub rotation: Quat,
    /// World-to-camera translation (COLMAP's `tvec`).
    pub translation: Vec3,
}

impl Camera {
    pub fn new(intrinsics: Intrinsics, rotation: Quat, translation: Vec3) -> Camera {
        Camera {
            intrinsics,
            rotation: rotation.normalize(),
            translation,
        }
    }

    /// The same camera seeing only the window `width × height` whose top-left pixel is
    /// `(x0, y0)`: the principal point moves with the window, so every pixel of the crop sees
    /// exactly what the same pixel of the full image sees (refinement renders only a hull's box).
    pub fn cropped(&self, x0: u32, y0: u32, width: u32, height: u32) -> Camera {
        let k = self.intrinsics;
        Camera {
            intrinsics: Intrinsics {
                width,
                height,
                cx: k.cx - x0 as f32,
                cy: k.cy - y0 as f32,
                ..k
            },
            ..*self
        }
    }

    /// World-to-camera rotation matrix.
    pub fn rotation_matrix(&self) -> Mat3 {
        Mat3::from_quat(self.rotation)
    }

    /// A world point in camera coordinates.
    pub fn world_to_camera(&self, p_world: Vec3) -> Vec3 {
        self.rotation * p_world + self.translation
    }

    /// Camera centre in world coordinates: `-Rᵀ t`.
    pub fn position(&self) -> Vec3 {
        -(self.rotation.inverse() * self.translation)
    }

    /// Projects a world point to pixel coordinates (pixel centres at +0.5, as in 3DGS/gsplat);
    /// `None` when the point is not in front of the camera.
    pub fn project(&self, p_world: Vec3) -> Option<glam::Vec2> {
        let p = self.world_to_camera(p_world);
        // `!(z > 0)` also rejects NaN.
        if !(p.z > 1e-6) {
            return None;
        }
        let k = &self.intrinsics;
        Some(glam::Vec2::new(
            k.fx * p.x / p.z + k.cx,
            k.fy * p.y / p.z + k.cy,
        ))
    }

    /// The pixel (column, row) a world point projects into, when it lands inside the image in
    /// front of the camera.
    pub fn pixel_of(&self, p_world: Vec3) -> Option<(u32, u32)> {
        let p = self.project(p_world)?;
        let k = &self.intrinsics;
        (p.x >= 0.0 && p.y >= 0.0 && p.x < k.width as f32 && p.y < k.height as f32)
            .then_some((p.x as u32, p.y as u32))
    }

    /// The same pose with intrinsics for another image size.
    pub fn resized(&self, width: u32, height: u32) -> Camera {
        Camera {
            intrinsics: self.intrinsics.resized(width, height),
            ..*self
        }
    }

    /// Builds a camera from an OpenGL camera-to-world matrix (nerfstudio, instant-ngp,
    /// NeRF-synthetic): OpenGL looks along -z with y up, so y and z axes flip before inverting.
    pub fn from_opengl_camera_to_world(intrinsics: Intrinsics, c2w: glam::Mat4) -> Camera {
        let flip = glam::Mat4::from_scale(Vec3::new(1.0, -1.0, -1.0));
        let c2w_colmap = c2w * flip;
        let w2c = c2w_colmap.inverse();
        let (_, rotation, translation) = w2c.to_scale_rotation_translation();
        Camera::new(intrinsics, rotation, translation)
    }

    /// Camera looking from `eye` at `target` with world `up` (for synthetic drone paths).
    pub fn look_at(intrinsics: Intrinsics, eye: Vec3, target: Vec3, up: Vec3) -> Camera {
        let forward = (target - eye).normalize();
        let right = forward.cross(up).normalize();
        let down = forward.cross(right);
        // Rows of the world-to-camera rotation are the camera axes in world coordinates.
        let r = Mat3::from_cols(right, down, forward).transpose();
        let rotation = Quat::from_mat3(&r);
        Camera::new(intrinsics, rotation, -(r * eye))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn intrinsics() -> Intrinsics {
        Intrinsics {
            width: 100,
            height: 80,
            fx: 90.0,
            fy: 90.0,
            cx: 50.0,
            cy: 40.0,
        }
    }

    #[test]
    fn look_at_puts_target_on_the_principal_point() {
        let eye = Vec3::new(3.0, -2.0, 5.0);
        let target = Vec3::new(0.5, 0.2, -1.0);
        let cam = Camera::look_at(intrinsics(), eye, target, Vec3::Z);
        let px = cam.project(target).unwrap();
        assert!((px - glam::Vec2::new(50.0, 40.0)).length() < 1e-3, "{px}");
        assert!((cam.position() - eye).length() < 1e-4);
    }

    #[test]
    fn opengl_pose_converts_to_colmap_axes() {
        // An OpenGL camera at (0,0,5) looking down -z at the origin, y up.
        let c2w = glam::Mat4::from_translation(Vec3::new(0.0, 0.0, 5.0));
        let cam = Camera::from_opengl_camera_to_world(intrinsics(), c2w);
        let origin = cam.world_to_camera(Vec3::ZERO);
        assert!(
            (origin - Vec3::new(0.0, 0.0, 5.0)).length() < 1e-5,
            "{origin}"
        );
        // World +y (up in OpenGL) must appear above the centre: smaller pixel y.
        let up = cam.project(Vec3::new(0.0, 1.0, 0.0)).unwrap();
        assert!(up.y < 40.0);
    }

    #[test]
    fn resizing_scales_all_intrinsics() {
        let k = intrinsics().resized(50, 40);
        assert_eq!((k.fx, k.fy, k.cx, k.cy), (45.0, 45.0, 25.0, 20.0));
    }
}
