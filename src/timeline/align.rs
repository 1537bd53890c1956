//! Placing a survey in the twin's frame. A joint COLMAP model (the old survey's images and the
//! new ones, reconstructed together: how users run COLMAP) is in a frame of its own; the images
//! it shares with the twin's survey give the similarity transform from that frame to the twin's
//! (Umeyama's least squares on camera centres, with gross mismatches trimmed), and the new
//! images' poses are mapped through it.

use glam::{DMat3, DQuat, DVec3, Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::scene::Camera;

/// `x_twin = scale · rotation · x_joint + translation`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Similarity {
    pub scale: f64,
    /// Unit quaternion `(x, y, z, w)`.
    pub rotation: [f64; 4],
    pub translation: [f64; 3],
}

impl Similarity {
    pub const IDENTITY: Similarity = Similarity {
        scale: 1.0,
        rotation: [0.0, 0.0, 0.0, 1.0],
        translation: [0.0; 3],
    };

    fn quat(&self) -> DQuat {
        DQuat::from_array(self.rotation).normalize()
    }

    /// A point of the joint frame in the twin's frame.
    pub fn apply(&self, p: DVec3) -> DVec3 {
        self.scale * (self.quat() * p) + DVec3::from_array(self.translation)
    }

    /// A joint-frame camera in the twin's frame: `x_cam = q·x + t` becomes
    /// `x_cam' = (q·R⁻¹)·x_twin + (s·t − q·R⁻¹·T)`; scaling the camera frame by `s` changes no
    /// pixel (a pinhole divides by depth).
    pub fn apply_camera(&self, camera: &Camera) -> Camera {
        let q = camera.rotation.as_dquat() * self.quat().inverse();
        let t =
            self.scale * camera.translation.as_dvec3() - q * DVec3::from_array(self.translation);
        Camera::new(
            camera.intrinsics,
            Quat::from_array(q.normalize().to_array().map(|v| v as f32)),
            Vec3::new(t.x as f32, t.y as f32, t.z as f32),
        )
    }
}

/// A fitted registration and how well it fits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Registration {
    pub similarity: Similarity,
    /// Images shared by both models, and how many the fit kept.
    pub shared: usize,
    pub inliers: usize,
    /// RMS distance (twin units) of the kept camera centres after the fit.
    pub residual: f64,
    /// The residual relative to the spread of the twin's camera centres (RMS distance to their
    /// mean): a scale-free measure of the fit.
    pub relative_residual: f64,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AlignError {
    #[error(
        "only {shared} image(s) of the joint model are also in the twin's survey: a similarity \
         needs at least 3 (name the images alike in both)"
    )]
    TooFewShared { shared: usize },
    #[error(
        "the joint model does not fit the twin: camera centres differ by {residual:.3} units RMS \
         after the best similarity, {relative:.1} % of the cameras' spread (at most {limit:.1} %)"
    )]
    PoorFit {
        residual: f64,
        relative: f64,
        limit: f64,
    },
    #[error("the shared cameras are degenerate (all at one place)")]
    Degenerate,
}

/// The largest relative residual accepted: 2 % of the cameras' spread. The synthetic joint
/// model's pose noise (1 cm on centres ~15 m apart) fits to ~0.1 %; a wrong match moves a centre
/// by metres.
pub const MAX_RELATIVE_RESIDUAL: f64 = 0.02;

/// Umeyama's similarity taking `from[i]` onto `to[i]` in least squares (Horn's quaternion
/// method for the rotation).
pub fn umeyama(from: &[DVec3], to: &[DVec3]) -> Option<Similarity> {
    let n = from.len();
    if n < 3 || to.len() != n {
        return None;
    }
    let mean_from = from.iter().copied().sum::<DVec3>() / n as f64;
    let mean_to = to.iter().copied().sum::<DVec3>() / n as f64;
    // Cross-covariance M = Σ x' y'ᵀ (x' = from − mean, y' = to − mean).
    let mut m = DMat3::ZERO;
    let mut var_from = 0.0;
    for (x, y) in from.iter().zip(to) {
        let (x, y) = (*x - mean_from, *y - mean_to);
        m += DMat3::from_cols(x * y.x, x * y.y, x * y.z);
        var_from += x.length_squared();
    }
    if !(var_from > 1e-18) {
        return None;
    }
    // Horn: the rotation is the eigenvector of the largest eigenvalue of N (4×4 symmetric).
    let s = |r: usize, c: usize| m.col(c)[r];
    let (sxx, sxy, sxz) = (s(0, 0), s(0, 1), s(0, 2));
    let (syx, syy, syz) = (s(1, 0), s(1, 1), s(1, 2));
    let (szx, szy, szz) = (s(2, 0), s(2, 1), s(2, 2));
    let n4 = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let (w, x, y, z) = largest_eigenvector(n4);
    let rotation = DQuat::from_xyzw(x, y, z, w).normalize();
    // Umeyama's scale: Σ y'·(R x') / Σ |x'|².
    let mut dot = 0.0;
    for (x, y) in from.iter().zip(to) {
        dot += (*y - mean_to).dot(rotation * (*x - mean_from));
    }
    let scale = dot / var_from;
    if !(scale > 0.0) {
        return None;
    }
    let translation = mean_to - scale * (rotation * mean_from);
    Some(Similarity {
        scale,
        rotation: rotation.to_array(),
        translation: translation.to_array(),
    })
}

/// The eigenvector `(w, x, y, z)` of the largest eigenvalue of a symmetric 4×4 matrix (cyclic
/// Jacobi rotations, to machine precision in a few sweeps). Indexed loops: the maths is written
/// in matrix indices.
#[allow(clippy::needless_range_loop)]
fn largest_eigenvector(mut a: [[f64; 4]; 4]) -> (f64, f64, f64, f64) {
    let mut v = [[0.0f64; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _ in 0..64 {
        let off: f64 = (0..4)
            .flat_map(|i| (0..4).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        if off < 1e-30 {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..4 {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..4 {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in v.iter_mut() {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let best = (0..4)
        .max_by(|&i, &j| a[i][i].total_cmp(&a[j][j]))
        .unwrap_or(0);
    (v[0][best], v[1][best], v[2][best], v[3][best])
}

/// Fits the similarity from the joint model's camera centres to the twin's, for the images both
/// hold (`pairs`: joint camera, twin camera). Up to a third of the pairs may be gross mismatches:
/// after each fit, pairs further than 3 × the median residual (and more than 0.5 % of the
/// spread) are dropped and the fit is repeated.
pub fn register(pairs: &[(Camera, Camera)]) -> Result<Registration, AlignError> {
    let shared = pairs.len();
    if shared < 3 {
        return Err(AlignError::TooFewShared { shared });
    }
    let from: Vec<DVec3> = pairs.iter().map(|(j, _)| j.position().as_dvec3()).collect();
    let to: Vec<DVec3> = pairs.iter().map(|(_, t)| t.position().as_dvec3()).collect();
    let mean_to = to.iter().copied().sum::<DVec3>() / shared as f64;
    let spread =
        (to.iter().map(|p| p.distance_squared(mean_to)).sum::<f64>() / shared as f64).sqrt();
    if !(spread > 1e-9) {
        return Err(AlignError::Degenerate);
    }
    let mut keep: Vec<usize> = (0..shared).collect();
    let mut fit = umeyama(&from, &to).ok_or(AlignError::Degenerate)?;
    for _ in 0..4 {
        let residuals: Vec<f64> = (0..shared)
            .map(|i| fit.apply(from[i]).distance(to[i]))
            .collect();
        let mut sorted: Vec<f64> = keep.iter().map(|&i| residuals[i]).collect();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        let limit = (3.0 * median).max(0.005 * spread);
        let next: Vec<usize> = (0..shared).filter(|&i| residuals[i] <= limit).collect();
        if next.len() < 3 || next == keep {
            break;
        }
        keep = next;
        let (f, t): (Vec<DVec3>, Vec<DVec3>) = keep.iter().map(|&i| (from[i], to[i])).unzip();
        fit = umeyama(&f, &t).ok_or(AlignError::Degenerate)?;
    }
    let residual = (keep
        .iter()
        .map(|&i| fit.apply(from[i]).distance_squared(to[i]))
        .sum::<f64>()
        / keep.len() as f64)
        .sqrt();
    let relative_residual = residual / spread;
    if !(relative_residual <= MAX_RELATIVE_RESIDUAL) || keep.len() * 3 < shared * 2 {
        return Err(AlignError::PoorFit {
            residual,
            relative: 100.0 * relative_residual,
            limit: 100.0 * MAX_RELATIVE_RESIDUAL,
        });
    }
    Ok(Registration {
        similarity: fit,
        shared,
        inliers: keep.len(),
        residual,
        relative_residual,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Intrinsics;

    fn cameras(n: usize, seed: u64) -> Vec<Camera> {
        let k = Intrinsics {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 24.0,
        };
        let mut rng = fastrand::Rng::with_seed(seed);
        (0..n)
            .map(|_| {
                let eye = Vec3::new(
                    rng.f32() * 30.0 - 15.0,
                    rng.f32() * 30.0 - 15.0,
                    5.0 + rng.f32() * 10.0,
                );
                Camera::look_at(k, eye, Vec3::ZERO, Vec3::Z)
            })
            .collect()
    }

    /// The inverse of `known` applied to twin cameras: their joint-frame versions.
    fn to_joint(known: &Similarity, twin: &Camera) -> Camera {
        let inverse_rotation = known.quat().inverse();
        let inverse = Similarity {
            scale: 1.0 / known.scale,
            rotation: inverse_rotation.to_array(),
            translation: (-(inverse_rotation * DVec3::from_array(known.translation)) / known.scale)
                .to_array(),
        };
        inverse.apply_camera(twin)
    }

    fn known() -> Similarity {
        Similarity {
            scale: 0.61,
            rotation: DQuat::from_euler(glam::EulerRot::XYZ, 0.4, -1.1, 2.3).to_array(),
            translation: [12.0, -40.0, 7.5],
        }
    }

    #[test]
    fn a_known_similarity_is_recovered_and_maps_cameras_back() {
        let twin = cameras(20, 1);
        let known = known();
        let pairs: Vec<(Camera, Camera)> = twin.iter().map(|t| (to_joint(&known, t), *t)).collect();
        let reg = register(&pairs).unwrap();
        assert_eq!(reg.inliers, 20);
        assert!((reg.similarity.scale - known.scale).abs() < 1e-6, "{reg:?}");
        assert!(reg.residual < 1e-4, "{reg:?}");
        for (joint, twin) in &pairs {
            let back = reg.similarity.apply_camera(joint);
            assert!(back.position().distance(twin.position()) < 1e-3);
            let angle = back.rotation.angle_between(twin.rotation);
            assert!(angle < 1e-4, "{angle}");
        }
    }

    #[test]
    fn a_few_bad_matches_are_trimmed() {
        let twin = cameras(24, 2);
        let known = known();
        let mut pairs: Vec<(Camera, Camera)> =
            twin.iter().map(|t| (to_joint(&known, t), *t)).collect();
        // Four images matched to the wrong camera.
        for i in 0..4 {
            pairs[i].1 = twin[(i + 10) % 24];
        }
        let reg = register(&pairs).unwrap();
        assert_eq!(reg.inliers, 20, "{reg:?}");
        assert!((reg.similarity.scale - known.scale).abs() < 1e-5, "{reg:?}");
        assert!(reg.relative_residual < 1e-5);
    }

    #[test]
    fn too_few_or_inconsistent_matches_are_refused() {
        let twin = cameras(12, 3);
        let known = known();
        let pairs: Vec<(Camera, Camera)> = twin.iter().map(|t| (to_joint(&known, t), *t)).collect();
        assert_eq!(
            register(&pairs[..2]),
            Err(AlignError::TooFewShared { shared: 2 })
        );
        // Every twin camera shuffled: no similarity fits.
        let shuffled: Vec<(Camera, Camera)> = pairs
            .iter()
            .enumerate()
            .map(|(i, (j, _))| (*j, twin[(i * 5 + 3) % 12]))
            .collect();
        assert!(matches!(
            register(&shuffled),
            Err(AlignError::PoorFit { .. })
        ));
    }
}
