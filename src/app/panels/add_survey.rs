//! The "Add survey…" dialog: a later survey's dataset folder (picked with a file dialog or typed),
//! its name, date and alignment, and "Segment with…" an ONNX model (classes, threshold), the
//! choices `twin add-survey` offers. From photos ("Add survey from photos…"): the photos and where
//! COLMAP's registered dataset goes instead, placed by that registration. While the survey is
//! added, its progress (COLMAP's stages) and a cancel button, and the COLMAP log one click away;
//! why it was not added, in red. Reads the state, queues commands.

use crate::app::commands::{Command, DialogKind};
use crate::app::panels::colmap_log::colmap_progress;
use crate::app::panels::path_row;
use crate::app::state::{AppState, TimelineJob, TimelineWork};
use crate::app::survey_form::AddSurveyForm;
use crate::timeline::survey::AlignMode;

#[derive(Default)]
pub struct AddSurveyPanel;

impl AddSurveyPanel {
    pub fn ui(&mut self, ctx: &egui::Context, state: &AppState, commands: &mut Vec<Command>) {
        let Some(form) = &state.add_survey else {
            return;
        };
        let running = state
            .timeline
            .as_ref()
            .and_then(|t| t.job.as_ref())
            .filter(|j| matches!(j.work, TimelineWork::AddSurvey(_)));
        let mut edited = form.clone();
        let mut open = true;
        let title = match form.from_photos {
            true => "Add survey from photos",
            false => "Add survey",
        };
        egui::Window::new(title)
            .open(&mut open)
            .collapsible(false)
            .resizable(false)
            .default_width(440.0)
            .show(ctx, |ui| {
                ui.add_enabled_ui(running.is_none(), |ui| fields(ui, &mut edited, commands));
                if let Some(problem) = &form.error {
                    ui.colored_label(ui.visuals().error_fg_color, problem);
                }
                ui.separator();
                match running {
                    Some(job) => progress(ui, job, form, commands),
                    None => {
                        ui.horizontal(|ui| {
                            if ui
                                .button("Add survey")
                                .on_hover_text(
                                    "Place the survey in the twin's frame and add it to the \
                                     project (its photos segmented first when asked)",
                                )
                                .clicked()
                            {
                                commands.push(Command::AddSurvey);
                            }
                            if ui.button("Close").clicked() {
                                commands.push(Command::CloseAddSurvey);
                            }
                            colmap_log_button(ui, form, commands);
                        });
                    }
                }
            });
        if edited != *form {
            commands.push(Command::EditAddSurvey(Box::new(edited)));
        }
        if !open {
            commands.push(Command::CloseAddSurvey);
        }
    }
}

/// The survey's fields and the segmentation's.
fn fields(ui: &mut egui::Ui, form: &mut AddSurveyForm, commands: &mut Vec<Command>) {
    egui::Grid::new("add-survey-fields")
        .num_columns(2)
        .spacing([8.0, 6.0])
        .show(ui, |ui| {
            if form.from_photos {
                path_row(
                    ui,
                    "Photos",
                    &mut form.photos,
                    "the later survey's photos",
                    Some(DialogKind::SurveyPhotos),
                    commands,
                );
                path_row(
                    ui,
                    "Registered dataset",
                    &mut form.dataset,
                    "a new folder",
                    None,
                    commands,
                );
            } else {
                path_row(
                    ui,
                    "Dataset folder",
                    &mut form.dataset,
                    "photos, poses and (optionally) masks",
                    Some(DialogKind::SurveyDataset),
                    commands,
                );
            }
            ui.label("Survey name");
            ui.add(egui::TextEdit::singleline(&mut form.name).desired_width(200.0));
            ui.end_row();
            ui.label("Date");
            ui.add(
                egui::TextEdit::singleline(&mut form.date)
                    .hint_text("YYYY-MM-DD")
                    .desired_width(120.0),
            );
            ui.end_row();
            ui.label("Alignment");
            if form.from_photos {
                ui.label("registered by COLMAP into the twin's posed survey")
                    .on_hover_text(align_hint(AlignMode::Colmap));
                ui.end_row();
                return;
            }
            egui::ComboBox::from_id_salt("add-survey-align")
                .selected_text(form.align.name())
                .show_ui(ui, |ui| {
                    for align in AlignMode::ALL {
                        ui.selectable_value(&mut form.align, align, align.name())
                            .on_hover_text(align_hint(align));
                    }
                })
                .response
                .on_hover_text(align_hint(form.align));
            ui.end_row();
        });
    ui.checkbox(&mut form.segment, "Segment with…")
        .on_hover_text(
            "Run an ONNX segmentation model on the survey's photos first: masks are written into \
             its dataset (never over masks already there)",
        );
    ui.add_enabled_ui(form.segment, |ui| {
        egui::Grid::new("add-survey-segment")
            .num_columns(2)
            .spacing([8.0, 6.0])
            .show(ui, |ui| {
                path_row(
                    ui,
                    "Model",
                    &mut form.model,
                    "model.onnx",
                    Some(DialogKind::SegmentModel),
                    commands,
                );
                ui.label("Classes");
                ui.add(egui::TextEdit::singleline(&mut form.classes).desired_width(200.0))
                    .on_hover_text(
                        "The class of each output channel: crack, or -,crack,spalling for a \
                         multi-class model (- for a channel not written)",
                    );
                ui.end_row();
                ui.label("Threshold");
                ui.add(egui::Slider::new(&mut form.threshold, 0.0..=1.0).step_by(0.01));
                ui.end_row();
            });
    });
}

fn align_hint(align: AlignMode) -> &'static str {
    match align {
        AlignMode::SameFrame => "The dataset's poses are already in the twin's frame",
        AlignMode::Joint => {
            "A COLMAP model of the latest survey's images and the new ones, registered through \
             the images they share"
        }
        AlignMode::Colmap => {
            "Photos already registered by COLMAP into a posed survey's model \
             (`twin add-survey --photos`)"
        }
    }
}

/// The add's progress (COLMAP's stages first, from photos) and its cancel button.
fn progress(
    ui: &mut egui::Ui,
    job: &TimelineJob,
    form: &AddSurveyForm,
    commands: &mut Vec<Command>,
) {
    ui.horizontal(|ui| {
        colmap_progress(ui, job.progress.as_ref());
        if ui.button("Cancel").clicked() {
            commands.push(Command::CancelTimelineJob);
        }
        colmap_log_button(ui, form, commands);
    });
}

/// "COLMAP log" for a survey from photos: the log of the run writing its dataset.
fn colmap_log_button(ui: &mut egui::Ui, form: &AddSurveyForm, commands: &mut Vec<Command>) {
    let dataset = form.dataset.trim();
    if form.from_photos
        && !dataset.is_empty()
        && ui
            .button("COLMAP log")
            .on_hover_text("What COLMAP printed registering the photos")
            .clicked()
    {
        commands.push(Command::ShowColmapLog(Some(dataset.into())));
    }
}
