//! A similarity transform (scale, rotation, translation) between two frames, and its fits:
//! Umeyama's least squares on matched points, and the trimmed fit that drops gross mismatches.
//! Used to place a survey in the twin's frame (`timeline::align`), to georeference an SfM model
//! from GPS or control points (`scene::sfm`), and to compare one model with another.

use glam::{DMat3, DQuat, DVec3, Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::scene::Camera;

/// `x_to = scale · rotation · x_from + translation` (from a joint or SfM frame to the twin's or a
/// metric frame).
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

    pub fn quat(&self) -> DQuat {
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

/// A trimmed fit (`fit_trimmed`): the similarity, which pairs it kept, and every pair's distance
/// after it (in the `to` frame's units).
#[derive(Clone, Debug, PartialEq)]
pub struct TrimmedFit {
    pub similarity: Similarity,
    pub kept: Vec<usize>,
    pub residuals: Vec<f64>,
}

impl TrimmedFit {
    /// RMS distance of the kept pairs after the fit.
    pub fn rms(&self) -> f64 {
        let n = self.kept.len().max(1) as f64;
        (self
            .kept
            .iter()
            .map(|&i| self.residuals[i].powi(2))
            .sum::<f64>()
            / n)
            .sqrt()
    }
}

/// RMS distance of `points` to their mean: the scale-free yardstick of a fit.
pub fn spread(points: &[DVec3]) -> f64 {
    let n = points.len().max(1) as f64;
    let mean = points.iter().copied().sum::<DVec3>() / n;
    (points.iter().map(|p| p.distance_squared(mean)).sum::<f64>() / n).sqrt()
}

/// Umeyama's fit with gross mismatches dropped: after each fit, pairs further than 3 × the
/// median residual (and more than `floor` in the `to` frame) are dropped and the fit is
/// repeated, at most four times. `None` for fewer than 3 pairs or a degenerate set.
pub fn fit_trimmed(from: &[DVec3], to: &[DVec3], floor: f64) -> Option<TrimmedFit> {
    let n = from.len();
    let mut keep: Vec<usize> = (0..n).collect();
    let mut fit = umeyama(from, to)?;
    let distances = |fit: &Similarity| -> Vec<f64> {
        (0..n).map(|i| fit.apply(from[i]).distance(to[i])).collect()
    };
    let mut residuals = distances(&fit);
    for _ in 0..4 {
        let mut sorted: Vec<f64> = keep.iter().map(|&i| residuals[i]).collect();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        let limit = (3.0 * median).max(floor);
        let next: Vec<usize> = (0..n).filter(|&i| residuals[i] <= limit).collect();
        if next.len() < 3 || next == keep {
            break;
        }
        keep = next;
        let (f, t): (Vec<DVec3>, Vec<DVec3>) = keep.iter().map(|&i| (from[i], to[i])).unzip();
        fit = umeyama(&f, &t)?;
        residuals = distances(&fit);
    }
    Some(TrimmedFit {
        similarity: fit,
        kept: keep,
        residuals,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn umeyama_recovers_a_known_similarity_and_trimming_drops_outliers() {
        let known = Similarity {
            scale: 2.5,
            rotation: DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.9).to_array(),
            translation: [4.0, -1.0, 9.0],
        };
        let mut rng = fastrand::Rng::with_seed(5);
        let from: Vec<DVec3> = (0..12)
            .map(|_| DVec3::new(rng.f64(), rng.f64(), rng.f64()) * 10.0)
            .collect();
        let mut to: Vec<DVec3> = from.iter().map(|p| known.apply(*p)).collect();
        let fit = umeyama(&from, &to).unwrap();
        assert!((fit.scale - 2.5).abs() < 1e-9, "{fit:?}");
        to[3] += DVec3::new(30.0, 0.0, 0.0);
        let trimmed = fit_trimmed(&from, &to, 1e-6).unwrap();
        assert_eq!(trimmed.kept.len(), 11, "{trimmed:?}");
        assert!(!trimmed.kept.contains(&3));
        assert!(trimmed.rms() < 1e-9);
        assert!((trimmed.similarity.scale - 2.5).abs() < 1e-9);
        assert!(umeyama(&from[..2], &to[..2]).is_none());
    }
}
