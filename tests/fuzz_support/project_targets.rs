//! The fuzz harness's twin-project targets (issue 45 §5): a project of two surveys over a small
//! `transforms.json` dataset, with each survey's model (a patch of crack Gaussians, so the
//! measurement runs), metrics (`twin new`'s and `twin update`'s shapes), training history and a
//! change map. A case mutates `twin.ron` or one survey file, then opens the project and does
//! what `report` and `twin status` do with it: every survey measured, every model, metrics file,
//! history and change map read, and the report's charts drawn.

use std::path::Path;

use damage_twin::report::project_runs::project_runs;
use damage_twin::report::tradeoff_chart::tradeoff_svg;
use damage_twin::report::training_chart::training_svg;
use damage_twin::scene::files::is_present;
use damage_twin::scene::load::load_image;
use damage_twin::scene::project::{ColourTransform, PROJECT_FILE};
use damage_twin::splats::Splats;
use damage_twin::timeline::Twin;
use damage_twin::timeline::detect_survey::change_map_path;
use damage_twin::timeline::quantities::survey_quantities;
use damage_twin::timeline::twin::{HISTORY_FILE, METRICS_FILE};
use damage_twin::train::history::{EvalSample, History, Sample};
use glam::{Quat, Vec3};

use super::mutate::Content;
use super::targets::{Target, seed, write_transforms_dataset};

/// A 6 × 6 patch of flat crack Gaussians in the plane z = 0, facing the dataset's cameras.
fn damaged_patch() -> Splats {
    let mut splats = Splats {
        label_channels: 3,
        ..Splats::default()
    };
    let flat = Vec3::new(0.06, 0.06, 0.005).ln();
    for i in 0..6u32 {
        for j in 0..6u32 {
            let mean = Vec3::new(i as f32 * 0.1 - 0.25, j as f32 * 0.1 - 0.25, 0.0);
            let crack = if i == j { 6.0 } else { -6.0 };
            splats.push(
                mean,
                flat,
                Quat::IDENTITY,
                4.0,
                &[0.3, 0.3, 0.3],
                &[crack, -6.0, -6.0],
                u64::from(i * 6 + j),
                0,
            );
        }
    }
    splats
}

fn history() -> History {
    History {
        samples: (0..4u32)
            .map(|k| Sample {
                wall_s: f64::from(k) * 1.5,
                step: k * 100,
                loss: 0.2 / f64::from(k + 1),
                psnr: 18.0 + f64::from(k),
                gaussians: 36 + k as usize,
            })
            .collect(),
        evals: vec![EvalSample {
            wall_s: 4.5,
            step: 300,
            psnr: 21.5,
        }],
    }
}

/// The project in `root` (its dataset in `root/data`), with files of both surveys.
fn write_project(root: &Path) {
    let data = root.join("data");
    write_transforms_dataset(&data);
    let mut twin = Twin::create(root).unwrap();
    twin.add_survey("s1", "2024-03-01", &data).unwrap();
    twin.add_survey("s2", "2024-09-15", &data).unwrap();
    for name in ["s1", "s2"] {
        twin.save_model(name, &damaged_patch()).unwrap();
        twin.save_history(name, &history()).unwrap();
    }
    twin.save_metrics(
        "s1",
        &serde_json::json!({
            "seconds": 400.0, "heldout_psnr": 25.0, "heldout_ssim": 0.8, "gaussians": 36,
            "iterations": 300, "scale": {"Factor": 1},
        }),
    )
    .unwrap();
    twin.save_metrics(
        "s2",
        &serde_json::json!({
            "seconds": 70.0,
            "refine": {
                "before": {"iou": {"crack": 0.3, "rebar": 0.2}, "psnr": 19.5},
                "after": {"iou": {"crack": 0.5, "rebar": null}, "psnr": 20.1},
            }
        }),
    )
    .unwrap();
    let changes = twin.survey_file("s2", "changes").unwrap();
    std::fs::create_dir_all(&changes).unwrap();
    image::RgbImage::from_fn(8, 6, |x, y| image::Rgb([x as u8 * 30, 0, y as u8 * 40]))
        .save(change_map_path(&changes, "im1"))
        .unwrap();
    twin.project.surveys[1].changes = Some(twin.relative(&changes));
    twin.project.surveys[1].appearance = Some(ColourTransform {
        offset: [0.05, -0.02, 0.01],
        ..ColourTransform::IDENTITY
    });
    twin.project.settings.metres_per_unit = Some(0.5);
    twin.save().unwrap();
}

/// What `report` and `twin status` read of the project, through the same library calls.
fn report_project(root: &Path, _: &Path) -> Result<(), String> {
    let text = |e: &dyn std::fmt::Display| e.to_string();
    let twin = Twin::open(root).map_err(|e| text(&e))?;
    survey_quantities(&twin).map_err(|e| text(&e))?;
    let mut points = Vec::new();
    for survey in &twin.project.surveys {
        let name = &survey.name;
        twin.load_model(name).map_err(|e| text(&e))?;
        if let Some(metrics) = twin.load_metrics(name).map_err(|e| text(&e))? {
            points.extend(project_runs(name, &metrics).iter().map(|r| r.point()));
        }
        if let Some(history) = twin.load_history(name).map_err(|e| text(&e))? {
            let file = twin.survey_file(name, HISTORY_FILE).map_err(|e| text(&e))?;
            training_svg(&file, &history).map_err(|e| text(&e))?;
        }
        if let Some(changes) = &survey.changes {
            let folder = twin.inside(changes).map_err(|e| text(&e))?;
            let map = change_map_path(&folder, "im1");
            if is_present(&map) {
                load_image(&map).map_err(|e| text(&e))?;
            }
        }
    }
    tradeoff_svg(&root.join("report.html"), &points).map_err(|e| text(&e))?;
    Ok(())
}

/// `twin.ron` mutated; the project opened and reported.
pub fn project_file_target() -> Target<String> {
    let dir = tempfile::tempdir().unwrap();
    write_project(dir.path());
    let seeds = vec![seed(dir.path(), PROJECT_FILE, Content::Text)];
    Target {
        name: "project_file",
        dir,
        seeds,
        read: report_project,
    }
}

/// One survey file mutated (metrics of both shapes, a history, a change map, a model); the
/// project opened and reported.
pub fn survey_files_target() -> Target<String> {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    write_project(root);
    let seeds = vec![
        seed(root, &format!("surveys/s1/{METRICS_FILE}"), Content::Text),
        seed(root, &format!("surveys/s2/{METRICS_FILE}"), Content::Text),
        seed(root, &format!("surveys/s1/{HISTORY_FILE}"), Content::Text),
        seed(root, "surveys/s2/changes/im1.png", Content::Binary),
        seed(root, "surveys/s2/model.ply", Content::Binary),
    ];
    Target {
        name: "survey_files",
        dir,
        seeds,
        read: report_project,
    }
}
