//! The viewport's navigation: orbit / pan / zoom around a target and fly (WASD/QE), as pure maths
//! on a pose (target, distance, yaw, pitch) that eases towards a goal frame-rate independently.
//! Knows nothing of egui: the viewport turns mouse and keys into a `CameraInput`.

use glam::{Quat, Vec2, Vec3};
use serde::{Deserialize, Serialize};

use crate::scene::{Camera, Intrinsics};

/// Pitch stays short of the poles so that `look_at` keeps a well-defined right vector.
const MAX_PITCH: f32 = 1.55;
const MIN_DISTANCE: f32 = 1e-3;

/// Orbit or fly: in orbit mode rotation pivots about the target, in fly mode about the eye.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum NavMode {
    #[default]
    Orbit,
    Fly,
}

/// The pose the controller eases towards (and the pose it has).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrbitPose {
    pub target: Vec3,
    pub distance: f32,
    /// Azimuth about `up`, radians.
    pub yaw: f32,
    /// Elevation above the plane normal to `up`, radians.
    pub pitch: f32,
}

/// One frame of user input, already in device-independent units.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraInput {
    /// Seconds since the previous frame.
    pub dt: f32,
    /// Rotate drag, in points.
    pub rotate: Vec2,
    /// Pan drag, in points.
    pub pan: Vec2,
    /// Scroll, in points (positive zooms in).
    pub zoom: f32,
    /// Fly axes in the camera frame: x right (D − A), y up (E − Q), z forward (W − S).
    pub fly: Vec3,
    /// Shift held: fly faster.
    pub boost: bool,
    /// Height of the viewport in points (pan follows the cursor at the target's depth).
    pub viewport_height: f32,
}

impl CameraInput {
    pub fn is_active(&self) -> bool {
        self.rotate != Vec2::ZERO
            || self.pan != Vec2::ZERO
            || self.zoom != 0.0
            || self.fly != Vec3::ZERO
    }
}

/// Orbit/fly camera with exponential easing.
#[derive(Clone, Debug)]
pub struct CameraController {
    pub mode: NavMode,
    /// World up (unit).
    pub up: Vec3,
    /// Vertical field of view, radians.
    pub fov_y: f32,
    /// Radians per point of drag.
    pub rotate_speed: f32,
    /// Fly speed in scene units per second (scaled by the distance to the target at reset).
    pub fly_speed: f32,
    /// Easing rate per second: the remaining distance to the goal decays as `exp(-rate · t)`.
    pub smoothing: f32,
    pose: OrbitPose,
    goal: OrbitPose,
}

impl CameraController {
    pub fn new(up: Vec3, pose: OrbitPose) -> CameraController {
        let up = if up.length_squared() > 1e-12 {
            up.normalize()
        } else {
            Vec3::Z
        };
        CameraController {
            mode: NavMode::Orbit,
            up,
            fov_y: 50f32.to_radians(),
            rotate_speed: 0.006,
            fly_speed: pose.distance.max(MIN_DISTANCE) * 0.5,
            smoothing: 18.0,
            pose,
            goal: pose,
        }
    }

    /// Frames a scene of the given centre and radius, looking from the side slightly above.
    pub fn framing(up: Vec3, centre: Vec3, radius: f32) -> CameraController {
        let mut c = CameraController::new(
            up,
            OrbitPose {
                target: centre,
                distance: 1.0,
                yaw: 0.6,
                pitch: 0.35,
            },
        );
        let half = c.fov_y * 0.5;
        let distance = (radius.max(MIN_DISTANCE) / half.sin()) * 1.1;
        c.goal.distance = distance;
        c.pose.distance = distance;
        c.fly_speed = distance * 0.5;
        c
    }

    pub fn pose(&self) -> OrbitPose {
        self.pose
    }

    /// Eases to orbit `target` at a distance that frames a sphere of `radius`, looking from
    /// `from` (a direction from the target to the eye; None keeps the view direction). A
    /// direction along `up` keeps the yaw.
    pub fn frame_target(&mut self, target: Vec3, radius: f32, from: Option<Vec3>) {
        self.goal.target = target;
        self.goal.distance = (radius.max(MIN_DISTANCE) / (self.fov_y * 0.5).sin()) * 1.1;
        if let Some(d) = from.and_then(|d| d.try_normalize()) {
            let (e1, e2) = self.basis();
            let pitch = d.dot(self.up).clamp(-1.0, 1.0).asin();
            let level = d - self.up * d.dot(self.up);
            if level.length_squared() > 1e-8 {
                // Keep the eased yaw within half a turn of the current one (no spin).
                let yaw = level.dot(e2).atan2(level.dot(e1));
                let turns = ((self.goal.yaw - yaw) / std::f32::consts::TAU).round();
                self.goal.yaw = yaw + turns * std::f32::consts::TAU;
            }
            self.goal.pitch = pitch;
        }
    }

    pub fn goal(&self) -> OrbitPose {
        self.goal
    }

    /// Jumps to a pose without easing.
    pub fn set_pose(&mut self, pose: OrbitPose) {
        self.pose = pose;
        self.goal = pose;
    }

    /// Orthonormal basis (e1, e2, up) in which yaw and pitch are measured.
    fn basis(&self) -> (Vec3, Vec3) {
        let up = self.up;
        let helper = if up.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
        let e1 = (helper - up * helper.dot(up)).normalize();
        let e2 = up.cross(e1);
        (e1, e2)
    }

    /// Unit vector from the target to the eye for a yaw and pitch.
    fn direction(&self, yaw: f32, pitch: f32) -> Vec3 {
        let (e1, e2) = self.basis();
        pitch.cos() * (yaw.cos() * e1 + yaw.sin() * e2) + pitch.sin() * self.up
    }

    pub fn eye_of(&self, pose: &OrbitPose) -> Vec3 {
        pose.target + pose.distance * self.direction(pose.yaw, pose.pitch)
    }

    pub fn eye(&self) -> Vec3 {
        self.eye_of(&self.pose)
    }

    /// Camera axes (right, up-on-screen, forward) of a pose, in world coordinates.
    fn axes(&self, pose: &OrbitPose) -> (Vec3, Vec3, Vec3) {
        let forward = -self.direction(pose.yaw, pose.pitch);
        let right = forward.cross(self.up).normalize();
        let screen_up = right.cross(forward);
        (right, screen_up, forward)
    }

    /// Applies one frame of input to the goal, then eases the pose towards it. Every rate is per
    /// second, so the same input spread over more, shorter frames reaches the same pose.
    pub fn update(&mut self, input: &CameraInput) {
        let dt = if input.dt.is_finite() {
            input.dt.clamp(0.0, 0.25)
        } else {
            0.0
        };
        let (right, screen_up, forward) = self.axes(&self.goal);

        if input.rotate != Vec2::ZERO {
            let eye = self.eye_of(&self.goal);
            self.goal.yaw -= input.rotate.x * self.rotate_speed;
            self.goal.pitch =
                (self.goal.pitch + input.rotate.y * self.rotate_speed).clamp(-MAX_PITCH, MAX_PITCH);
            if self.mode == NavMode::Fly {
                // Look around from a fixed eye: move the target instead.
                let d = self.direction(self.goal.yaw, self.goal.pitch);
                self.goal.target = eye - d * self.goal.distance;
            }
        }
        if input.pan != Vec2::ZERO && input.viewport_height > 0.0 {
            // World units per point at the target's depth, so the target follows the cursor.
            let per_point =
                2.0 * self.goal.distance * (self.fov_y * 0.5).tan() / input.viewport_height;
            self.goal.target += (-input.pan.x * right + input.pan.y * screen_up) * per_point;
        }
        if input.zoom != 0.0 && input.zoom.is_finite() {
            let factor = (-input.zoom * 0.002).exp();
            match self.mode {
                NavMode::Orbit => {
                    self.goal.distance = (self.goal.distance * factor).max(MIN_DISTANCE);
                }
                NavMode::Fly => {
                    // Dolly: move eye and target together.
                    let step = self.goal.distance * (1.0 - factor);
                    self.goal.target += forward * step;
                }
            }
        }
        if input.fly != Vec3::ZERO {
            let speed = self.fly_speed * if input.boost { 4.0 } else { 1.0 };
            let v = right * input.fly.x + self.up * input.fly.y + forward * input.fly.z;
            self.goal.target += v * speed * dt;
        }

        let t = 1.0 - (-self.smoothing.max(0.0) * dt).exp();
        let p = &mut self.pose;
        let g = &self.goal;
        p.target = p.target.lerp(g.target, t);
        p.distance += (g.distance - p.distance) * t;
        p.yaw += (g.yaw - p.yaw) * t;
        p.pitch += (g.pitch - p.pitch) * t;
    }

    /// True while the pose has not reached its goal (the viewport keeps repainting).
    pub fn is_moving(&self) -> bool {
        let p = &self.pose;
        let g = &self.goal;
        let scale = g.distance.max(MIN_DISTANCE);
        (p.target - g.target).length() > 1e-4 * scale
            || (p.distance - g.distance).abs() > 1e-4 * scale
            || (p.yaw - g.yaw).abs() > 1e-4
            || (p.pitch - g.pitch).abs() > 1e-4
    }

    /// The render camera for an image of `width × height` pixels (square pixels, centred).
    pub fn camera(&self, width: u32, height: u32) -> Camera {
        let width = width.max(1);
        let height = height.max(1);
        let f = 0.5 * height as f32 / (self.fov_y * 0.5).tan();
        let intrinsics = Intrinsics {
            width,
            height,
            fx: f,
            fy: f,
            cx: 0.5 * width as f32,
            cy: 0.5 * height as f32,
        };
        Camera::look_at(intrinsics, self.eye(), self.pose.target, self.up)
    }

    /// Moves to (approximately: roll is dropped) a survey camera's pose, keeping the distance to
    /// the target, so that leaving a snapped view continues smoothly.
    pub fn snap_to(&mut self, camera: &Camera) {
        let eye = camera.position();
        let forward = camera.rotation.inverse() * Vec3::Z;
        let back = -forward.normalize_or(Vec3::X);
        let (e1, e2) = self.basis();
        let pitch = back
            .dot(self.up)
            .clamp(-1.0, 1.0)
            .asin()
            .clamp(-MAX_PITCH, MAX_PITCH);
        let yaw = back.dot(e2).atan2(back.dot(e1));
        let distance = self.goal.distance.max(MIN_DISTANCE);
        let dir = self.direction(yaw, pitch);
        self.set_pose(OrbitPose {
            target: eye - dir * distance,
            distance,
            yaw,
            pitch,
        });
    }
}

/// Estimates the world up from survey cameras: the mean of their "up on screen" axes (−y in
/// COLMAP's camera frame). Drone photos are mostly level, so this is robust; falls back to +z.
pub fn estimate_up(cameras: &[Camera]) -> Vec3 {
    let sum: Vec3 = cameras
        .iter()
        .map(|c| c.rotation.inverse() * Vec3::NEG_Y)
        .filter(|v| v.is_finite())
        .sum();
    if sum.length() > 1e-3 * cameras.len().max(1) as f32 {
        sum.normalize()
    } else {
        Vec3::Z
    }
}

/// The rotation from the camera frame to the world frame (for drawing frusta).
pub fn camera_to_world(camera: &Camera) -> Quat {
    camera.rotation.inverse()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_looks_at_target() {
        let c = CameraController::framing(Vec3::Z, Vec3::new(1.0, 2.0, 3.0), 2.0);
        let cam = c.camera(200, 100);
        let px = cam.project(Vec3::new(1.0, 2.0, 3.0)).unwrap();
        assert!((px - Vec2::new(100.0, 50.0)).length() < 1e-2, "{px}");
    }
}
