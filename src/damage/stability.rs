//! The stability suite (issue 24 §3): one twin per setting, each axis moved alone from the
//! baseline run, scored on the same held-out views (PSNR, SSIM, damage IoU against the clean
//! masks). An axis shows where quality breaks: fewer training views, noisy training poses, a
//! coarser training scale, a textureless building. The held-out views and their poses are never
//! perturbed, so every row is scored against the same truth. Reads no files beyond the dataset.

use std::collections::BTreeMap;

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::damage::assess::{EvalRequest, evaluate_model};
use crate::damage::evaluate::DamageReadout;
use crate::damage::setup::{RunConfig, prepare_run};
use crate::damage::{Palette, TrainMode};
use crate::scene::{Camera, Dataset};
use crate::train::job::JobOptions;
use crate::train::run::train;
use crate::train::spec::TrainView;

/// One row of the study.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StabilityRow {
    /// `textureless`, `views`, `pose_noise`, `mask_noise` or `scale`.
    pub axis: String,
    /// The axis's setting: 0/1 (textured/flat colours), training views, degrees of pose noise,
    /// mask corruption rate, or the training image's downscale factor.
    pub value: f64,
    /// Held-out PSNR (dB) and SSIM, against the photos (SSIM absent on rows taken from the
    /// mask-noise study, which does not measure it).
    pub psnr: f64,
    pub ssim: Option<f64>,
    /// Held-out IoU per damage class against the clean masks.
    pub iou: BTreeMap<String, f64>,
    pub gaussians: usize,
    /// Training time, held-out evaluation excluded.
    pub seconds: f64,
    /// Training image size.
    pub width: u32,
    pub height: u32,
}

/// What a run changes from the baseline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Perturbation {
    None,
    /// Train on this many of the training views, evenly spread over the capture.
    Views(usize),
    /// Rotate each training camera by this many degrees about a random axis and move its centre
    /// by the same angle times its distance to the scene's centre, in a random direction: a
    /// pose error that shifts the scene by about the same amount on screen from both terms.
    PoseNoise {
        degrees: f32,
        seed: u64,
    },
}

/// Trains `config` on `dataset` with `perturbation` applied to the training views and scores
/// the result on the held-out views. `axis` and `value` name the row.
pub fn stability_run(
    dataset: &Dataset,
    config: &RunConfig,
    perturbation: Perturbation,
    axis: &str,
    value: f64,
    threads: Option<usize>,
) -> Result<StabilityRow, String> {
    let name = |e: String| format!("{axis} = {value}: {e}");
    let mut run = prepare_run(dataset, config).map_err(|e| name(e.to_string()))?;
    perturb(&mut run.setup.views, perturbation).map_err(name)?;
    let views = &run.setup.views;
    let (width, height) = (views[0].image.width, views[0].image.height);
    let heldout_indices = run.heldout_indices.clone();
    run.setup.heldout.clear(); // scored below, once, not during training
    let outcome = train(run.setup, JobOptions::headless(threads))
        .wait()
        .map_err(|e| name(e.to_string()))?;
    let readout = DamageReadout {
        mode: run.mode,
        ..DamageReadout::for_model(&outcome.splats, Palette::default())
    };
    let scores = evaluate_model(
        dataset,
        &outcome.splats,
        &EvalRequest {
            indices: heldout_indices,
            scale: config.scale,
            background: config.background,
            sh_degree: config.sh_degree,
            photometric: true,
            half_appearance: false,
            readout,
        },
        &mut |_, _| {},
    )
    .map_err(|e| name(e.to_string()))?;
    Ok(StabilityRow {
        axis: axis.to_string(),
        value,
        psnr: scores.psnr.unwrap_or(f64::NAN),
        ssim: scores.ssim,
        iou: match (&scores.damage, run.mode) {
            (Some(d), TrainMode::Label | TrainMode::Overlay) => d.iou.clone(),
            _ => BTreeMap::new(),
        },
        gaussians: outcome.splats.len(),
        seconds: outcome.seconds,
        width,
        height,
    })
}

/// Applies `perturbation` to a run's training views.
pub fn perturb(views: &mut Vec<TrainView>, perturbation: Perturbation) -> Result<(), String> {
    match perturbation {
        Perturbation::None => {}
        Perturbation::Views(n) => {
            if n == 0 || n > views.len() {
                return Err(format!(
                    "{n} training views asked for, {} available",
                    views.len()
                ));
            }
            *views = spread(std::mem::take(views), n);
        }
        Perturbation::PoseNoise { degrees, seed } => {
            let centre = scene_centre(views.iter().map(|v| &v.camera));
            let mut rng = fastrand::Rng::with_seed(seed);
            for view in views.iter_mut() {
                view.camera = perturb_pose(&view.camera, centre, degrees, &mut rng);
            }
        }
    }
    Ok(())
}

/// `n` of `items`, evenly spread (the first always kept).
fn spread<T>(items: Vec<T>, n: usize) -> Vec<T> {
    let len = items.len();
    let keep: Vec<usize> = (0..n).map(|i| i * len / n).collect();
    items
        .into_iter()
        .enumerate()
        .filter(|(i, _)| keep.contains(i))
        .map(|(_, item)| item)
        .collect()
}

/// The point the cameras look at, roughly: the mean of their centres (a capture circles its
/// subject).
fn scene_centre<'a>(cameras: impl Iterator<Item = &'a Camera>) -> Vec3 {
    let (sum, n) = cameras.fold((Vec3::ZERO, 0usize), |(s, n), c| (s + c.position(), n + 1));
    sum / n.max(1) as f32
}

/// A unit vector uniformly on the sphere.
fn random_direction(rng: &mut fastrand::Rng) -> Vec3 {
    loop {
        let v = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 2.0 - Vec3::ONE;
        let len = v.length();
        if len > 1e-3 && len <= 1.0 {
            return v / len;
        }
    }
}

/// `camera` rotated by `degrees` about a random axis through its centre, and its centre moved
/// by `degrees` (in radians) × its distance to `centre` in a random direction.
pub fn perturb_pose(
    camera: &Camera,
    centre: Vec3,
    degrees: f32,
    rng: &mut fastrand::Rng,
) -> Camera {
    let angle = degrees.to_radians();
    let turn = Quat::from_axis_angle(random_direction(rng), angle);
    let old_centre = camera.position();
    let moved = old_centre + random_direction(rng) * angle * old_centre.distance(centre);
    // World-to-camera: x_cam = R x + t, centre c = −Rᵀ t.
    let rotation = (camera.rotation * turn).normalize();
    let translation = -(rotation * moved);
    Camera::new(camera.intrinsics, rotation, translation)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Intrinsics;

    #[test]
    fn spread_keeps_evenly_spaced_items() {
        assert_eq!(spread((0..10).collect(), 5), vec![0, 2, 4, 6, 8]);
        assert_eq!(spread((0..10).collect(), 10), (0..10).collect::<Vec<_>>());
        assert_eq!(
            spread((0..52).collect(), 8),
            vec![0, 6, 13, 19, 26, 32, 39, 45]
        );
    }

    #[test]
    fn pose_noise_turns_and_moves_by_the_asked_amount() {
        let intrinsics = Intrinsics {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 24.0,
        };
        let camera = Camera::new(
            intrinsics,
            Quat::from_rotation_y(0.3),
            Vec3::new(0.5, 0.0, 4.0),
        );
        let centre = Vec3::ZERO;
        let mut rng = fastrand::Rng::with_seed(1);
        for degrees in [0.25f32, 1.0, 2.0] {
            let noisy = perturb_pose(&camera, centre, degrees, &mut rng);
            let turned = camera.rotation.angle_between(noisy.rotation).to_degrees();
            assert!((turned - degrees).abs() < 1e-2, "{turned} vs {degrees}");
            let moved = camera.position().distance(noisy.position());
            let expected = degrees.to_radians() * camera.position().distance(centre);
            assert!((moved - expected).abs() < 1e-4, "{moved} vs {expected}");
        }
        let same = perturb_pose(&camera, centre, 0.0, &mut rng);
        assert!(same.position().distance(camera.position()) < 1e-5);
    }
}
