//! Placing a survey in the twin's frame. A joint COLMAP model (the old survey's images and the
//! new ones, reconstructed together: how users run COLMAP) is in a frame of its own; the images
//! it shares with the twin's survey give the similarity transform from that frame to the twin's
//! (Umeyama's least squares on camera centres, with gross mismatches trimmed), and the new
//! images' poses are mapped through it.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::scene::Camera;
pub use crate::scene::similarity::{Similarity, umeyama};
use crate::scene::similarity::{fit_trimmed, spread};

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
    let spread = spread(&to);
    if !(spread > 1e-9) {
        return Err(AlignError::Degenerate);
    }
    let trimmed = fit_trimmed(&from, &to, 0.005 * spread).ok_or(AlignError::Degenerate)?;
    let residual = trimmed.rms();
    let (fit, keep) = (trimmed.similarity, trimmed.kept);
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
    use glam::{DQuat, Vec3};

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
