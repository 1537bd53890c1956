//! The "New twin from photos…" dialog: a folder of photos (picked with a file dialog or typed),
//! where the posed dataset and the twin project go, the first survey's name and date, and
//! whether to train once posed. While COLMAP runs, its stage and a Cancel button; the COLMAP log
//! one click away; why no twin was made, in one red line. Reads the state, queues commands.

use crate::app::commands::{Command, DialogKind};
use crate::app::panels::colmap_log::colmap_progress;
use crate::app::panels::path_row;
use crate::app::state::AppState;
use crate::app::twin_form::NewTwinForm;

#[derive(Default)]
pub struct NewTwinPanel;

impl NewTwinPanel {
    pub fn ui(&mut self, ctx: &egui::Context, state: &AppState, commands: &mut Vec<Command>) {
        let Some(dialog) = &state.new_twin else {
            return;
        };
        let running = dialog.run.as_ref();
        let mut edited = dialog.form.clone();
        let mut open = true;
        egui::Window::new("New twin from photos")
            .open(&mut open)
            .collapsible(false)
            .resizable(false)
            .default_width(460.0)
            .show(ctx, |ui| {
                ui.add_enabled_ui(running.is_none(), |ui| fields(ui, &mut edited, commands));
                if let Some(problem) = &dialog.form.error {
                    ui.colored_label(ui.visuals().error_fg_color, problem);
                }
                ui.separator();
                ui.horizontal(|ui| {
                    match running {
                        Some(run) => {
                            colmap_progress(ui, run.progress.as_ref());
                            if ui.button("Cancel").clicked() {
                                commands.push(Command::CancelNewTwin);
                            }
                        }
                        None => {
                            if ui
                                .button("Pose and make the twin")
                                .on_hover_text(
                                    "COLMAP poses the photos into the dataset (as `damage-twin \
                                     pose`), then the twin project is made from it",
                                )
                                .clicked()
                            {
                                commands.push(Command::NewTwinFromPhotos);
                            }
                            if ui.button("Close").clicked() {
                                commands.push(Command::CloseNewTwin);
                            }
                        }
                    }
                    if let Some(dataset) = &dialog.last_dataset
                        && ui
                            .button("COLMAP log")
                            .on_hover_text("What COLMAP printed for this dataset")
                            .clicked()
                    {
                        commands.push(Command::ShowColmapLog(Some(dataset.clone())));
                    }
                });
            });
        if edited != dialog.form {
            commands.push(Command::EditNewTwin(Box::new(edited)));
        }
        if !open {
            commands.push(Command::CloseNewTwin);
        }
    }
}

fn fields(ui: &mut egui::Ui, form: &mut NewTwinForm, commands: &mut Vec<Command>) {
    egui::Grid::new("new-twin-fields")
        .num_columns(2)
        .spacing([8.0, 6.0])
        .show(ui, |ui| {
            path_row(
                ui,
                "Photos",
                &mut form.photos,
                "a folder of overlapping photos",
                Some(DialogKind::TwinPhotos),
                commands,
            );
            path_row(
                ui,
                "Posed dataset",
                &mut form.dataset,
                "a new folder",
                None,
                commands,
            );
            path_row(
                ui,
                "Twin project",
                &mut form.project,
                "a new folder",
                None,
                commands,
            );
            ui.label("First survey");
            ui.add(egui::TextEdit::singleline(&mut form.survey).desired_width(200.0));
            ui.end_row();
            ui.label("Date");
            ui.add(
                egui::TextEdit::singleline(&mut form.date)
                    .hint_text("YYYY-MM-DD")
                    .desired_width(120.0),
            );
            ui.end_row();
        });
    ui.checkbox(&mut form.train, "Train the twin once posed");
}
