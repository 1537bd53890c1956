//! Project and surveys: open a dataset / project / model (dialogs; drag-and-drop is handled by the
//! app), recent files, save and export, and the survey views (clicking one snaps the viewport
//! to it), the twin's georeference and its surveys' COLMAP registrations, "New twin from
//! photos…". Reads the state, queues commands.

use crate::app::commands::{Command, DialogKind};
use crate::app::state::{AppState, ProjectRecords};
use crate::scene::Dataset;
use crate::scene::sfm::GeorefSource;

#[derive(Default)]
pub struct ProjectPanel;

impl ProjectPanel {
    pub fn ui(&mut self, ui: &mut egui::Ui, state: &AppState, commands: &mut Vec<Command>) {
        file_buttons(ui, state, commands);

        let Some(scene) = &state.scene else {
            ui.weak("Nothing open. Drop a dataset folder, twin.ron or .ply here.");
            return;
        };
        ui.separator();
        ui.label(format!("Source: {}", scene.source.display()));
        if let Some(dir) = &scene.project_dir {
            ui.label(format!("Twin: {}", dir.display()));
        }
        if let Some(records) = state.timeline.as_ref().and_then(|t| t.records.as_ref()) {
            frame_records(ui, records);
        }
        let Some(dataset) = &scene.dataset else {
            return;
        };
        ui.label(format!(
            "{} views · {:?} · masks: {}",
            dataset.views.len(),
            dataset.format,
            if dataset.mask_counts.is_empty() {
                "none".to_string()
            } else {
                dataset
                    .mask_counts
                    .iter()
                    .map(|(c, n)| format!("{} {n}", c.id()))
                    .collect::<Vec<_>>()
                    .join(", ")
            }
        ));
        survey_views(ui, dataset, state, commands);
    }
}

/// Opening (dialogs and recent paths), saving and exporting.
fn file_buttons(ui: &mut egui::Ui, state: &AppState, commands: &mut Vec<Command>) {
    ui.horizontal_wrapped(|ui| {
        if ui
            .button("Open folder…")
            .on_hover_text("A dataset (COLMAP, transforms.json) or a twin folder")
            .clicked()
        {
            commands.push(Command::ShowDialog(DialogKind::OpenFolder));
        }
        if ui
            .button("Open file…")
            .on_hover_text("twin.ron or a .ply model")
            .clicked()
        {
            commands.push(Command::ShowDialog(DialogKind::OpenFile));
        }
        if ui
            .button("New twin from photos…")
            .on_hover_text(
                "Pose a folder of photos with COLMAP (as `damage-twin pose`) and make a twin                  project of them",
            )
            .clicked()
        {
            commands.push(Command::OpenNewTwin);
        }
    });
    if !state.settings.recent.is_empty() {
        ui.collapsing("Recent", |ui| {
            for path in &state.settings.recent {
                let label = path
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_else(|| path.display().to_string());
                if ui
                    .link(label)
                    .on_hover_text(path.display().to_string())
                    .clicked()
                {
                    commands.push(Command::Open(path.clone()));
                }
            }
        });
    }
    let has_model = state.splats.is_some();
    ui.horizontal_wrapped(|ui| {
        ui.add_enabled_ui(has_model, |ui| {
            if ui.button("Save twin").clicked() {
                commands.push(Command::SaveProjectHere);
            }
            if ui.button("Save as…").clicked() {
                commands.push(Command::ShowDialog(DialogKind::SaveProject));
            }
            if ui.button("Export PLY…").clicked() {
                commands.push(Command::ShowDialog(DialogKind::ExportPly));
            }
            if ui.button("Export PNG…").clicked() {
                commands.push(Command::ShowDialog(DialogKind::ExportPng));
            }
        });
    });
}

/// The dataset's survey views: clicking one snaps the viewport to it (again: leaves it).
fn survey_views(
    ui: &mut egui::Ui,
    dataset: &Dataset,
    state: &AppState,
    commands: &mut Vec<Command>,
) {
    let snapped = state.snap.as_ref().map(|s| s.view);
    egui::CollapsingHeader::new("Survey views")
        .default_open(false)
        .show(ui, |ui| {
            egui::ScrollArea::vertical()
                .max_height(180.0)
                .show(ui, |ui| {
                    for (i, view) in dataset.views.iter().enumerate() {
                        if ui
                            .selectable_label(snapped == Some(i), &view.name)
                            .on_hover_text("Look through this camera and compare with its photo")
                            .clicked()
                        {
                            commands.push(if snapped == Some(i) {
                                Command::Unsnap
                            } else {
                                Command::SnapToView(i)
                            });
                        }
                    }
                });
        });
}

/// The twin's georeference (source, origin, residual, the scale's trust) and the residual of
/// each survey registered by COLMAP.
fn frame_records(ui: &mut egui::Ui, records: &ProjectRecords) {
    match &records.georeference {
        Ok(Some(geo)) => {
            let g = &geo.georeference;
            let source = match g.source {
                GeorefSource::Gps => "GPS",
                GeorefSource::ControlPoints => "control points",
                GeorefSource::LocalControlPoints => "control points (local frame)",
            };
            ui.label(format!("Georeference: {source} (survey {})", geo.survey))
                .on_hover_text(geo.trust());
            if g.source != GeorefSource::LocalControlPoints {
                ui.label(format!(
                    "Origin: {:.6}°, {:.6}°, {:.1} m",
                    g.latitude, g.longitude, g.altitude
                ));
            }
            ui.label(format!(
                "Residual {:.2} m RMS over {} positions ({} rejected) · {:.4} m per unit · scale \
                 ±{:.1} %",
                g.rms_m,
                g.used.len(),
                g.rejected.len(),
                geo.metres_per_unit(),
                100.0 * g.scale_uncertainty
            ))
            .on_hover_text(geo.trust());
        }
        Ok(None) => {
            ui.weak("Georeference: none (no GPS or control points: lengths in model units)");
        }
        Err(e) => {
            ui.colored_label(ui.visuals().error_fg_color, format!("Georeference: {e}"));
        }
    }
    for (survey, residual) in &records.registrations {
        ui.label(format!("Registration of {survey}: {residual}"));
    }
}
