//! `--survey2-frame joint`: survey 2 as a user's COLMAP run over the old and new images would give
//! it. One model of survey 1's images and survey 2's (`new-view-NNN.png`) in a seeded random
//! similarity frame, with small seeded pose noise, and the similarity recorded in
//! `truth/joint_frame.json`. Poses, points, names and file copies only; no rendering.

use std::path::Path;

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

use super::generate::view_name;
use super::params::SynthError;
use crate::scene::colmap::ColmapModel;

/// Image file name of survey 2's view `index` in the joint model (survey 1 keeps `view-NNN.png`).
pub fn new_view_name(index: usize) -> String {
    format!("new-{}", view_name(index))
}

/// Pose noise: 0.1° RMS rotation and 1 cm RMS camera-centre error (over the three axes), the
/// order of a good COLMAP reconstruction of a building photographed from 10-15 m.
const ROTATION_RMS_DEGREES: f64 = 0.1;
const TRANSLATION_RMS_M: f64 = 0.01;
/// Scale range of the random frame (log-uniform) and its offset from the origin.
const SCALE_RANGE: (f64, f64) = (0.3, 3.0);
const OFFSET_RANGE_M: (f64, f64) = (20.0, 60.0);

/// `x_joint = scale * rotation * x_twin + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Similarity {
    pub scale: f64,
    pub rotation: DQuat,
    pub translation: DVec3,
}

impl Similarity {
    /// A seeded random frame: uniform rotation, log-uniform scale in `SCALE_RANGE`, translation
    /// in a random direction at `OFFSET_RANGE_M` (joint units).
    pub fn random(seed: u64) -> Similarity {
        let mut rng = fastrand::Rng::with_seed(seed ^ 0x5117_F4A3);
        // A normalised 4D Gaussian is a uniformly random rotation.
        let q = DQuat::from_xyzw(
            gauss(&mut rng),
            gauss(&mut rng),
            gauss(&mut rng),
            gauss(&mut rng),
        );
        let rotation = q.normalize();
        let (lo, hi) = (SCALE_RANGE.0.ln(), SCALE_RANGE.1.ln());
        let scale = (lo + (hi - lo) * rng.f64()).exp();
        let dir = DVec3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)).normalize();
        let distance = OFFSET_RANGE_M.0 + (OFFSET_RANGE_M.1 - OFFSET_RANGE_M.0) * rng.f64();
        Similarity {
            scale,
            rotation,
            translation: dir * distance,
        }
    }

    pub fn apply(&self, p: DVec3) -> DVec3 {
        self.scale * (self.rotation * p) + self.translation
    }

    pub fn inverse_apply(&self, p: DVec3) -> DVec3 {
        self.rotation.inverse() * (p - self.translation) / self.scale
    }

    /// A world-to-camera pose `(q, t)` of the twin frame as the same camera in the joint frame:
    /// `q' = q · rotation⁻¹`, `t' = scale · t − q' · translation`.
    pub fn pose(&self, q: DQuat, t: DVec3) -> (DQuat, DVec3) {
        let q_joint = (q * self.rotation.inverse()).normalize();
        (q_joint, self.scale * t - q_joint * self.translation)
    }

    /// The inverse of `pose`.
    pub fn inverse_pose(&self, q_joint: DQuat, t_joint: DVec3) -> (DQuat, DVec3) {
        let q = (q_joint * self.rotation).normalize();
        (q, (t_joint + q_joint * self.translation) / self.scale)
    }
}

/// `truth/joint_frame.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointFrame {
    pub maps: String,
    pub scale: f64,
    /// (w, x, y, z).
    pub rotation_wxyz: [f64; 4],
    pub translation: [f64; 3],
    pub pose_noise: PoseNoise,
    /// Survey 1's images in the model, under their survey-1 names.
    pub old_images: Vec<String>,
    /// Survey 2's images, renamed.
    pub new_images: Vec<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseNoise {
    pub applied: String,
    pub rotation_sigma_degrees_per_axis: f64,
    pub translation_sigma_m_per_axis: f64,
    pub rotation_rms_degrees: f64,
    pub translation_rms_m: f64,
    pub seed: u64,
}

impl JointFrame {
    pub fn new(
        sim: &Similarity,
        seed: u64,
        old_images: Vec<String>,
        new_images: Vec<String>,
    ) -> Self {
        let q = sim.rotation;
        JointFrame {
            maps: "twin (survey 1 world, metres) frame -> joint frame: \
                x_joint = scale * R(rotation_wxyz) * x_twin + translation; a world-to-camera pose \
                (q, t) maps to (q * rotation^-1, scale * t - (q * rotation^-1) * translation)"
                .to_string(),
            scale: sim.scale,
            rotation_wxyz: [q.w, q.x, q.y, q.z],
            translation: sim.translation.to_array(),
            pose_noise: PoseNoise {
                applied: "to every image of the joint model, in the twin frame before the \
                    similarity: camera centre + N(0, sigma) per axis (metres), orientation \
                    turned about the camera's own axes by N(0, sigma) per axis; sparse points \
                    are mapped through the similarity only"
                    .to_string(),
                rotation_sigma_degrees_per_axis: per_axis(ROTATION_RMS_DEGREES),
                translation_sigma_m_per_axis: per_axis(TRANSLATION_RMS_M),
                rotation_rms_degrees: ROTATION_RMS_DEGREES,
                translation_rms_m: TRANSLATION_RMS_M,
                seed: noise_seed(seed),
            },
            old_images,
            new_images,
        }
    }

    pub fn similarity(&self) -> Similarity {
        let [w, x, y, z] = self.rotation_wxyz;
        Similarity {
            scale: self.scale,
            rotation: DQuat::from_xyzw(x, y, z, w).normalize(),
            translation: DVec3::from_array(self.translation),
        }
    }

    pub fn write(&self, path: &Path) -> Result<(), SynthError> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| SynthError::InvalidParams(format!("{}: {e}", path.display())))?;
        std::fs::write(path, text + "\n").map_err(|source| SynthError::Io {
            path: path.to_path_buf(),
            source,
        })
    }
}

/// The per-axis sigma of a 3D Gaussian whose norm has RMS `rms`.
fn per_axis(rms: f64) -> f64 {
    rms / 3f64.sqrt()
}

fn noise_seed(seed: u64) -> u64 {
    seed ^ 0x9015_E000
}

/// Survey 1's model followed by survey 2's (both in the twin frame), re-numbered into one
/// model, every pose given noise and every pose and point mapped into the joint frame.
pub fn joint_model(
    old: &ColmapModel,
    new: &ColmapModel,
    sim: &Similarity,
    seed: u64,
) -> ColmapModel {
    let mut rng = fastrand::Rng::with_seed(noise_seed(seed));
    let image_offset = old.images.len() as u32;
    let point_offset = old.points.len() as u64;
    let mut model = ColmapModel {
        cameras: old.cameras.clone(),
        images: Vec::with_capacity(old.images.len() + new.images.len()),
        points: Vec::with_capacity(old.points.len() + new.points.len()),
    };
    for (part, (image_shift, point_shift)) in [(old, (0, 0)), (new, (image_offset, point_offset))] {
        for image in &part.images {
            let mut image = image.clone();
            let [w, x, y, z] = image.qvec;
            let q = DQuat::from_xyzw(x, y, z, w).normalize();
            let t = DVec3::from_array(image.tvec);
            let (q, t) = noisy_pose(q, t, &mut rng);
            let (q, t) = sim.pose(q, t);
            image.id += image_shift;
            image.qvec = [q.w, q.x, q.y, q.z];
            image.tvec = t.to_array();
            for (_, point) in &mut image.points2d {
                if *point >= 0 {
                    *point += point_shift as i64;
                }
            }
            model.images.push(image);
        }
        for point in &part.points {
            let mut point = point.clone();
            point.id += point_shift;
            point.xyz = sim.apply(DVec3::from_array(point.xyz)).to_array();
            for (image, _) in &mut point.track {
                *image += image_shift;
            }
            model.points.push(point);
        }
    }
    model
}

/// The pose of a camera whose centre moved by N(0, σ_t) per axis and which turned about its
/// own axes by N(0, σ_r) per axis.
fn noisy_pose(q: DQuat, t: DVec3, rng: &mut fastrand::Rng) -> (DQuat, DVec3) {
    let centre = -(q.inverse() * t);
    let turn = DVec3::new(gauss(rng), gauss(rng), gauss(rng))
        * per_axis(ROTATION_RMS_DEGREES).to_radians();
    let shift = DVec3::new(gauss(rng), gauss(rng), gauss(rng)) * per_axis(TRANSLATION_RMS_M);
    let q_noisy = (DQuat::from_scaled_axis(turn) * q).normalize();
    (q_noisy, -(q_noisy * (centre + shift)))
}

fn gauss(rng: &mut fastrand::Rng) -> f64 {
    let u1 = rng.f64().max(1e-12);
    let u2 = rng.f64();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Copies survey 1's images and written masks into survey 2's folders, byte for byte.
pub fn copy_old_views(
    survey1: &Path,
    survey2: &Path,
    names: &[String],
    classes: &[&str],
) -> Result<(), SynthError> {
    let mut dirs = vec![std::path::PathBuf::from("images")];
    dirs.extend(classes.iter().map(|c| Path::new("masks").join(c)));
    for dir in &dirs {
        for name in names {
            let from = survey1.join(dir).join(name);
            let to = survey2.join(dir).join(name);
            std::fs::copy(&from, &to).map_err(|source| SynthError::Io {
                path: from.clone(),
                source,
            })?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_and_points_map_consistently_and_invert() {
        let sim = Similarity::random(7);
        assert!(sim.scale >= 0.3 && sim.scale <= 3.0);
        let q = DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0);
        let t = DVec3::new(1.0, -2.0, 15.0);
        let p = DVec3::new(3.0, 4.0, 5.0);
        // The camera-frame point of p is the same up to the scale in both frames.
        let cam = q * p + t;
        let (qj, tj) = sim.pose(q, t);
        let cam_joint = qj * sim.apply(p) + tj;
        assert!((cam_joint - sim.scale * cam).length() < 1e-9);
        let (qb, tb) = sim.inverse_pose(qj, tj);
        assert!(qb.dot(q).abs() > 1.0 - 1e-12 && (tb - t).length() < 1e-9);
        assert!((sim.inverse_apply(sim.apply(p)) - p).length() < 1e-9);
    }
}
