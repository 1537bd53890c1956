//! The "Add survey…" dialog: a later survey's dataset folder (picked with a file dialog or typed),
//! its name, date and alignment, and "Segment with…" an ONNX model (classes, threshold), the
//! choices `twin add-survey` offers. While the survey is added, its progress and a cancel button;
//! why it was not added, in red. Reads the state, queues commands.

use crate::app::commands::{Command, DialogKind};
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
        egui::Window::new("Add survey")
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
                    Some(job) => progress(ui, job, commands),
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
            ui.label("Dataset folder");
            ui.horizontal(|ui| {
                ui.add(
                    egui::TextEdit::singleline(&mut form.dataset)
                        .hint_text("photos, poses and (optionally) masks")
                        .desired_width(280.0),
                );
                if ui.button("Choose…").clicked() {
                    commands.push(Command::ShowDialog(DialogKind::SurveyDataset));
                }
            });
            ui.end_row();
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
                ui.label("Model");
                ui.horizontal(|ui| {
                    ui.add(
                        egui::TextEdit::singleline(&mut form.model)
                            .hint_text("model.onnx")
                            .desired_width(280.0),
                    );
                    if ui.button("Choose…").clicked() {
                        commands.push(Command::ShowDialog(DialogKind::SegmentModel));
                    }
                });
                ui.end_row();
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

/// The add's progress and its cancel button.
fn progress(ui: &mut egui::Ui, job: &TimelineJob, commands: &mut Vec<Command>) {
    ui.horizontal(|ui| {
        let (fraction, text) = match &job.progress {
            Some(p) if p.phase == "segment" => (
                p.step as f32 / p.total.max(1) as f32,
                format!("segmenting photo {}/{}", p.step, p.total),
            ),
            Some(_) => (1.0, "adding the survey to the project".to_string()),
            None => (0.0, "starting…".to_string()),
        };
        ui.add(
            egui::ProgressBar::new(fraction)
                .text(text)
                .desired_width(320.0),
        );
        if ui.button("Cancel").clicked() {
            commands.push(Command::CancelTimelineJob);
        }
    });
}
