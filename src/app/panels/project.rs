//! Project and surveys: open a dataset / project / model (dialogs; drag-and-drop is handled by the
//! app), recent files, save and export, and the survey views (clicking one snaps the viewport
//! to it). Reads the state, queues commands.

use crate::app::commands::{Command, DialogKind};
use crate::app::state::AppState;
use crate::scene::Dataset;

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
