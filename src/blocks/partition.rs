//! Cutting a posed dataset into blocks along its long axis: the frame (the cameras' mean up, the
//! principal horizontal direction of the cameras and points), the cuts (equal lengths, or
//! balanced so each block holds as many points), and each training photo assigned to every
//! block whose enlarged box it sees (VastGaussian's visibility rule: enough of what the photo
//! sees lies in the box).

use glam::{Mat3, Vec3};

use crate::blocks::plan::{
    Block, BlockTraining, ContextTraining, Frame, PLAN_FORMAT, PLAN_VERSION, Plan,
};
use crate::scene::Dataset;
use crate::train::views::{Holdout, split_views};

/// Most points the partition looks at (a stride over the dataset's points beyond it).
const MAX_POINTS: usize = 20_000;

/// The share of the points a photo sees that must lie in a block's enlarged box for the photo to
/// join it (`partition --min-share`, and a later survey's plan: `replan`).
pub const DEFAULT_MIN_SHARE: f32 = 0.1;

/// Where the cuts go along the long axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// Blocks of equal length over the structure's extent.
    Grid,
    /// Blocks holding equal numbers of the structure's points (dense parts get short blocks).
    Balanced,
}

impl std::str::FromStr for Split {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "grid" => Ok(Split::Grid),
            "balanced" => Ok(Split::Balanced),
            _ => Err(format!("unknown split {text:?}: use grid or balanced")),
        }
    }
}

/// How to partition.
#[derive(Clone, Debug)]
pub struct PartitionConfig {
    pub blocks: usize,
    pub split: Split,
    /// Margin on each side as a fraction of a block's length.
    pub margin_fraction: f32,
    /// Seam band half width as a fraction of the margin.
    pub band_fraction: f32,
    /// A photo belongs to a block when at least this share of the points it sees lie in the
    /// block's enlarged box.
    pub min_share: f32,
    pub min_photos: usize,
    pub training: BlockTraining,
    /// The context run every block renders frozen behind its own (None: none).
    pub context: Option<ContextTraining>,
}

/// The plan of `dataset` (opened from `dataset_path`, absolute) under `config`.
pub fn partition(
    dataset: &Dataset,
    dataset_path: &std::path::Path,
    config: &PartitionConfig,
) -> Result<Plan, String> {
    let n_blocks = config.blocks.clamp(1, crate::blocks::plan::MAX_BLOCKS);
    let holdout = Holdout::Auto {
        every: config.training.test_every,
    };
    let (train, _) = split_views(dataset, &holdout)?;
    let centres: Vec<Vec3> = dataset.views.iter().map(|v| v.camera.position()).collect();
    let points = structure_points(dataset, &centres);
    let frame = frame_of(dataset, &centres, &points);
    // The structure's extent along its axis is where the cameras flew: points beyond (a ground
    // plane, far background) fall into the open outer blocks instead of stretching the cuts.
    let along_of = |p: Vec3| frame.coordinates(p).x;
    let (along_lo, along_hi) = centres
        .iter()
        .map(|&c| along_of(c))
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !(along_hi > along_lo) {
        return Err("the cameras have no extent along the structure's long axis".into());
    }
    let local: Vec<Vec3> = points.iter().map(|&p| frame.coordinates(p)).collect();
    let structure: Vec<Vec3> = local
        .iter()
        .copied()
        .filter(|c| c.x >= along_lo && c.x <= along_hi)
        .collect();
    // Across and up: the 2nd to 98th percentile of the structure's points.
    let range = |axis: usize| -> [f32; 2] {
        let mut v: Vec<f32> = structure.iter().map(|c| c[axis]).collect();
        if v.is_empty() {
            return [0.0, 0.0];
        }
        v.sort_by(f32::total_cmp);
        [
            v[v.len() * 2 / 100],
            v[(v.len() * 98 / 100).min(v.len() - 1)],
        ]
    };
    let cuts = match config.split {
        Split::Grid => (0..=n_blocks)
            .map(|k| along_lo + (along_hi - along_lo) * k as f32 / n_blocks as f32)
            .collect::<Vec<f32>>(),
        Split::Balanced => {
            let mut along: Vec<f32> = structure.iter().map(|c| c.x).collect();
            if along.len() < n_blocks {
                along = centres.iter().map(|&c| along_of(c)).collect();
            }
            along.sort_by(f32::total_cmp);
            let mut cuts: Vec<f32> = (0..=n_blocks)
                .map(|k| along[((along.len() - 1) * k) / n_blocks])
                .collect();
            cuts[0] = along_lo;
            cuts[n_blocks] = along_hi;
            cuts.dedup();
            cuts
        }
    };
    let shortest = cuts
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f32::INFINITY, f32::min);
    let margin = config.margin_fraction.max(0.0) * shortest;
    let mut plan = Plan {
        format: PLAN_FORMAT.into(),
        version: PLAN_VERSION,
        dataset: dataset_path.to_path_buf(),
        frame,
        margin,
        seam_band: config.band_fraction.max(0.0) * margin,
        min_photos: config.min_photos,
        cross_range: range(1),
        up_range: range(2),
        training: config.training.clone(),
        context: config.context.clone(),
        blocks: cuts
            .windows(2)
            .enumerate()
            .map(|(index, w)| Block {
                index,
                start: w[0],
                end: w[1],
                photos: Vec::new(),
                skipped: None,
            })
            .collect(),
    };
    assign_photos(&mut plan, dataset, &train, &points, config.min_share);
    Ok(plan)
}

/// The plan of a later survey of the same structure (`dataset`, opened from `dataset_path`, in
/// `previous`'s frame): `previous`'s frame, cuts, margins and training settings, each block given
/// the new survey's photos that see it by the rule `partition` uses, so block K of both plans
/// covers the same part of the structure (`twin update` retrains a changed block on it).
pub fn replan(
    previous: &Plan,
    dataset: &Dataset,
    dataset_path: &std::path::Path,
    min_share: f32,
) -> Result<Plan, String> {
    let holdout = Holdout::Auto {
        every: previous.training.test_every,
    };
    let (train, _) = split_views(dataset, &holdout)?;
    let centres: Vec<Vec3> = dataset.views.iter().map(|v| v.camera.position()).collect();
    let points = structure_points(dataset, &centres);
    let mut plan = Plan {
        dataset: dataset_path.to_path_buf(),
        blocks: previous
            .blocks
            .iter()
            .map(|b| Block {
                photos: Vec::new(),
                skipped: None,
                ..b.clone()
            })
            .collect(),
        // The update's changed blocks train without a context: the previous survey's context
        // is of the old photos, and the update trains none of its own (docs/CLUSTER.md).
        context: None,
        ..previous.clone()
    };
    assign_photos(&mut plan, dataset, &train, &points, min_share);
    Ok(plan)
}

/// Gives each block of `plan` the training views (`train`, indices into `dataset`) that see its
/// enlarged box: at least `min_share` of the `points` a photo sees lie in the box, or, for a
/// photo seeing none, it was taken there. Blocks left with fewer than the plan's `min_photos`
/// are skipped.
fn assign_photos(
    plan: &mut Plan,
    dataset: &Dataset,
    train: &[usize],
    points: &[Vec3],
    min_share: f32,
) {
    let local: Vec<Vec3> = points.iter().map(|&p| plan.frame.coordinates(p)).collect();
    for &view in train {
        let camera = &dataset.views[view].camera;
        let seen: Vec<f32> = points
            .iter()
            .zip(&local)
            .filter(|(p, _)| camera.pixel_of(**p).is_some())
            .map(|(_, c)| c.x)
            .collect();
        for k in 0..plan.blocks.len() {
            let inside = seen.iter().filter(|&&a| plan.trains_on(k, a)).count();
            let sees = if seen.is_empty() {
                // A photo that sees none of the points: by where it was taken.
                plan.trains_on(k, plan.frame.coordinates(camera.position()).x)
            } else {
                inside > 0 && inside as f32 >= min_share * seen.len() as f32
            };
            if sees {
                plan.blocks[k].photos.push(dataset.views[view].name.clone());
            }
        }
    }
    let min_photos = plan.min_photos;
    for block in &mut plan.blocks {
        if block.photos.len() < min_photos {
            block.skipped = Some(format!(
                "{} photos, fewer than the {} a block needs",
                block.photos.len(),
                min_photos
            ));
        }
    }
}

/// The points the structure is cut by: the dataset's (a stride of at most `MAX_POINTS`), else
/// the camera centres.
fn structure_points(dataset: &Dataset, centres: &[Vec3]) -> Vec<Vec3> {
    match dataset.points.as_ref().filter(|p| !p.is_empty()) {
        Some(points) => {
            let stride = points.positions.len().div_ceil(MAX_POINTS).max(1);
            points.positions.iter().step_by(stride).copied().collect()
        }
        None => centres.to_vec(),
    }
}

/// The frame: up is the cameras' mean up (their −y axis in the world; COLMAP's y is down),
/// long the principal direction of the camera centres in the plane across it (a survey flies
/// along the structure; the points, with their ground and background, only when there are too
/// few cameras to say).
fn frame_of(dataset: &Dataset, centres: &[Vec3], points: &[Vec3]) -> Frame {
    let mut up: Vec3 = dataset
        .views
        .iter()
        .map(|v| v.camera.rotation.inverse() * Vec3::NEG_Y)
        .sum();
    up = up.normalize_or(Vec3::Z);
    let all: Vec<Vec3> = if centres.len() >= 3 {
        centres.to_vec()
    } else {
        centres.iter().chain(points).copied().collect()
    };
    let mean = all.iter().copied().sum::<Vec3>() / all.len().max(1) as f32;
    let flat = |p: Vec3| {
        let d = p - mean;
        d - up * d.dot(up)
    };
    let mut cov = Mat3::ZERO;
    for &p in &all {
        let d = flat(p);
        cov += Mat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    // The dominant eigenvector by power iteration, started off any axis.
    let seed = up.any_orthonormal_vector();
    let mut long = seed;
    for _ in 0..64 {
        let next = cov * long;
        let next = next - up * next.dot(up);
        if next.length() < 1e-12 {
            break;
        }
        long = next.normalize();
    }
    // Sign fixed so the same dataset gives the same frame: long points to larger x, then y.
    if long.x < -1e-6 || (long.x.abs() <= 1e-6 && long.y < 0.0) {
        long = -long;
    }
    let cross = up.cross(long).normalize();
    Frame {
        origin: mean.to_array(),
        long: long.to_array(),
        cross: cross.to_array(),
        up: up.to_array(),
    }
}
