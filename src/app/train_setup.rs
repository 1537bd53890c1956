//! Builds a training run from a dataset and the viewer's training settings (views at a scale with
//! the every-8th held-out rule, targets for the mode, initial splats from the dataset's points or
//! a random box). Runs on the training worker; shared by the app and the headless demo.

use crossbeam_channel::Sender;

use crate::app::settings::{TrainMode, TrainingSettings};
use crate::damage::DamageClass;
use crate::scene::{Dataset, ImageScale, PointCloud};
use crate::splats::init::{InitOptions, from_points, random_points};
use crate::train::job::{JobEvent, TrainSetup};
use crate::train::spec::{TrainSpec, TrainView};
use crate::train::views::{Holdout, load_views, split_views};

/// Random initial points when the dataset has none (3DGS uses 100k for NeRF-synthetic; a few
/// thousand converge faster on a CPU and densification adds the rest).
const RANDOM_POINTS: usize = 5_000;

fn log(log: Option<&Sender<JobEvent>>, line: String) {
    if let Some(tx) = log {
        let _ = tx.send(JobEvent::Log(line));
    }
}

/// Everything the job needs, loaded and initialised.
pub fn setup(
    dataset: &Dataset,
    settings: &TrainingSettings,
    background: [f32; 3],
    log_tx: Option<&Sender<JobEvent>>,
) -> Result<TrainSetup, String> {
    let scale = ImageScale::Factor(settings.resolution_factor.max(1));
    let (train_indices, heldout_indices) = split_views(dataset, &Holdout::Auto { every: 8 })?;
    let has_masks = dataset.mask_counts.values().any(|&n| n > 0);
    let mode = match settings.mode {
        TrainMode::Label | TrainMode::Overlay if !has_masks => {
            log(
                log_tx,
                format!(
                    "no damage masks in {}: training RGB only",
                    dataset.root.display()
                ),
            );
            TrainMode::Rgb
        }
        m => m,
    };
    let labels = mode != TrainMode::Rgb;
    log(
        log_tx,
        format!(
            "loading {} training and {} held-out views at {scale:?} ({} mode)",
            train_indices.len(),
            heldout_indices.len(),
            mode.name()
        ),
    );
    let mut views =
        load_views(dataset, &train_indices, scale, labels).map_err(|e| e.to_string())?;
    let mut heldout =
        load_views(dataset, &heldout_indices, scale, labels).map_err(|e| e.to_string())?;
    if mode == TrainMode::Overlay {
        for view in views.iter_mut().chain(heldout.iter_mut()) {
            paint_overlay(view);
        }
    }

    let label_channels = if mode == TrainMode::Label {
        DamageClass::ALL.len()
    } else {
        0
    };
    let points = match &dataset.points {
        Some(p) if !p.is_empty() => p.clone(),
        _ => {
            let centres: Vec<glam::Vec3> =
                dataset.views.iter().map(|v| v.camera.position()).collect();
            let extent = crate::train::densify::camera_extent(&centres);
            let centre = centres.iter().copied().sum::<glam::Vec3>() / centres.len().max(1) as f32;
            let mut cloud: PointCloud = random_points(RANDOM_POINTS, 0.5 * extent.max(1e-3), 0);
            for p in &mut cloud.positions {
                *p += centre;
            }
            log(
                log_tx,
                format!("no points in the dataset: {RANDOM_POINTS} random ones"),
            );
            cloud
        }
    };
    let splats = from_points(
        &points,
        &InitOptions {
            label_channels,
            ..InitOptions::default()
        },
    )
    .map_err(|e| e.to_string())?;

    let mut spec = TrainSpec::reconstruction(settings.iterations.max(1));
    spec.scale = scale;
    spec.background = glam::Vec3::from_array(background);
    spec.targets.label_weight = if label_channels > 0 {
        settings.label_weight
    } else {
        0.0
    };
    // Ten held-out evaluations over the run for the PSNR chart.
    spec.eval_every = (settings.iterations / 10).max(1);
    if label_channels == 0 {
        for view in views.iter_mut().chain(heldout.iter_mut()) {
            view.labels.clear();
        }
    }
    Ok(TrainSetup {
        spec,
        splats,
        views,
        heldout,
    })
}

/// Overlay mode (the published method): the masks painted into the photo in the class colours
/// (DESIGN.md defaults), which becomes the RGB target; the label masks are dropped.
fn paint_overlay(view: &mut TrainView) {
    for (class, mask) in DamageClass::ALL.iter().zip(&view.labels) {
        if mask.width != view.image.width || mask.height != view.image.height {
            continue;
        }
        let colour = class.default_colour().map(|c| f32::from(c) / 255.0);
        for (px, &m) in mask.data.iter().enumerate() {
            if m != 0 {
                view.image.data[px * 3..px * 3 + 3].copy_from_slice(&colour);
            }
        }
    }
    view.labels.clear();
}
