//! Turns a `Dataset` into in-memory training and held-out views at one scale, with the held-out
//! rule (NeRF-synthetic test split, else every n-th view, or views named by the user). Loads every
//! image once, up front, so the training loop never touches the disk.

use rayon::prelude::*;

use crate::scene::DamageClass;
use crate::scene::{Dataset, ImageScale, Mask, SceneError, Split};
use crate::train::spec::TrainView;

/// Which views are held out from training for evaluation.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Holdout {
    /// The dataset's test split when it has one (NeRF-synthetic), else every n-th view
    /// (index % n == 0, the 3DGS convention with n = 8).
    Auto { every: usize },
    /// Exactly the views with these names (image stems, e.g. `0049`); an unknown name is an error.
    Named(Vec<String>),
    /// Train on everything.
    None,
}

/// Indices of (training views, held-out views) in `dataset.views`.
pub fn split_views(
    dataset: &Dataset,
    holdout: &Holdout,
) -> Result<(Vec<usize>, Vec<usize>), String> {
    let n = dataset.views.len();
    let heldout: Vec<bool> = match holdout {
        Holdout::None => vec![false; n],
        Holdout::Auto { every } => {
            if dataset.views.iter().any(|v| v.split == Split::Test) {
                dataset
                    .views
                    .iter()
                    .map(|v| v.split == Split::Test)
                    .collect()
            } else if *every == 0 {
                vec![false; n]
            } else {
                (0..n).map(|i| i % every == 0).collect()
            }
        }
        Holdout::Named(names) => {
            let mut flags = vec![false; n];
            for name in names {
                let index = dataset.view_index(name).ok_or_else(|| {
                    format!(
                        "no view named {name:?} in {} (views are named like {})",
                        dataset.root.display(),
                        dataset.example_view_names()
                    )
                })?;
                flags[index] = true;
            }
            flags
        }
    };
    let train: Vec<usize> = (0..n).filter(|&i| !heldout[i]).collect();
    let test: Vec<usize> = (0..n).filter(|&i| heldout[i]).collect();
    if train.is_empty() {
        return Err(format!(
            "no training views left in {} after holding out {} views",
            dataset.root.display(),
            test.len()
        ));
    }
    Ok((train, test))
}

/// Loads views (in parallel) at `scale`. With `labels`, every view gets one mask per damage class
/// (an empty mask where the class has none), in `DamageClass::ALL` order.
pub fn load_views(
    dataset: &Dataset,
    indices: &[usize],
    scale: ImageScale,
    labels: bool,
) -> Result<Vec<TrainView>, SceneError> {
    indices
        .par_iter()
        .map(|&index| {
            let mut loaded = dataset.load_view(index, scale)?;
            let (w, h) = (loaded.image.width, loaded.image.height);
            let label_masks = if labels {
                DamageClass::ALL
                    .iter()
                    .map(|class| {
                        loaded
                            .masks
                            .remove(class)
                            .unwrap_or_else(|| Mask::empty(w, h))
                    })
                    .collect()
            } else {
                Vec::new()
            };
            Ok(TrainView {
                name: loaded.name,
                camera: loaded.camera,
                image: loaded.image,
                labels: label_masks,
                // Ignored pixels (ignore masks: pedestrians, cars, sky) take no part in any loss.
                region: loaded.ignore,
                light: None,
            })
        })
        .collect()
}

/// Options for the initial model of a from-scratch run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitialModel {
    /// Storage SH degree.
    pub sh_degree: u32,
    /// Damage label channels (0: appearance only).
    pub label_channels: usize,
    /// Random points when the dataset has none (3DGS uses 100 000 for NeRF-synthetic).
    pub random_points: usize,
    pub seed: u64,
}

/// The initial Gaussians: the dataset's points (SfM, or nerfstudio's `ply_file_path`), else
/// random points in a cube around where the cameras look (the least-squares meeting point of
/// their optical axes), sized to a third of the median camera distance to it — for
/// NeRF-synthetic (cameras at radius 4 around the origin) that is 3DGS's `[-1.3, 1.3]³`.
pub fn initial_splats(
    dataset: &Dataset,
    views: &[TrainView],
    options: &InitialModel,
) -> Result<crate::splats::Splats, crate::splats::init::InitError> {
    use crate::splats::init::{InitOptions, from_points, try_random_points};
    let init = InitOptions {
        sh_degree: options.sh_degree,
        label_channels: options.label_channels,
        ..InitOptions::default()
    };
    if let Some(points) = dataset.points.as_ref().filter(|p| !p.is_empty()) {
        return from_points(&points.positions, &points.colours, &init);
    }
    let (centre, half) = look_at_box(views);
    let (mut positions, colours) = try_random_points(options.random_points, half, options.seed)?;
    for p in &mut positions {
        *p += centre;
    }
    from_points(&positions, &colours, &init)
}

/// Centre and half size of the box the cameras look at (see `initial_splats`).
pub fn look_at_box(views: &[TrainView]) -> (glam::Vec3, f32) {
    use glam::{Mat3, Vec3};
    // Minimise Σ |(I - d dᵀ)(x - c)|² over the optical axes (c, d).
    let mut a = Mat3::ZERO;
    let mut b = Vec3::ZERO;
    for v in views {
        let c = v.camera.position();
        let d = (v.camera.rotation.inverse() * Vec3::Z).normalize();
        let m = Mat3::IDENTITY - Mat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += m;
        b += m * c;
    }
    let centre = if a.determinant().abs() > 1e-6 {
        a.inverse() * b
    } else {
        Vec3::ZERO
    };
    let centre = if centre.is_finite() {
        centre
    } else {
        Vec3::ZERO
    };
    let mut distances: Vec<f32> = views
        .iter()
        .map(|v| v.camera.position().distance(centre))
        .filter(|d| d.is_finite())
        .collect();
    distances.sort_by(f32::total_cmp);
    let median = distances.get(distances.len() / 2).copied().unwrap_or(3.9);
    (centre, (median / 3.0).max(1e-3))
}
