//! The timeline strip of a twin project: its surveys by date (click one, or < >, to show the
//! twin as of that survey), a survey to compare with side by side or by swipe, damage coloured
//! by survey, the change maps, and the timeline's jobs (detect changes, update the twin) with
//! their progress, and "Add survey…" (its dialog is `add_survey`). Reads the state, queues
//! commands.

use crate::app::commands::Command;
use crate::app::panels::edit_settings;
use crate::app::settings::SurveyLayout;
use crate::app::state::{AppState, TimelineJob, TimelineView};
use crate::damage::refine::Strategy;

pub struct TimelinePanel {
    strategy: Strategy,
    iterations: u32,
}

impl Default for TimelinePanel {
    fn default() -> Self {
        TimelinePanel {
            strategy: Strategy::Finetune,
            iterations: crate::timeline::update::UPDATE_ITERATIONS,
        }
    }
}

impl TimelinePanel {
    pub fn ui(&mut self, ui: &mut egui::Ui, state: &AppState, commands: &mut Vec<Command>) {
        let Some(timeline) = &state.timeline else {
            return;
        };
        ui.horizontal_wrapped(|ui| {
            survey_strip(ui, timeline, commands);
            ui.separator();
            compare_controls(ui, timeline, state, commands);
        });
        if let Some(holder) = &timeline.watch.holder {
            ui.colored_label(
                ui.visuals().warn_fg_color,
                format!(
                    "the project is being updated by {holder}: the timeline is read again when \
                     it finishes"
                ),
            );
        }
        ui.horizontal_wrapped(|ui| match &timeline.job {
            Some(job) => job_progress(ui, job, commands),
            None => self.job_buttons(ui, timeline.current, commands),
        });
    }

    /// Detect changes, and update the twin with its strategy and steps (both for a survey after
    /// the first).
    fn job_buttons(&mut self, ui: &mut egui::Ui, current: usize, commands: &mut Vec<Command>) {
        if ui
            .button("Add survey…")
            .on_hover_text(
                "A later survey's dataset, placed in the twin's frame (its photos segmented \
                 first, when asked)",
            )
            .clicked()
        {
            commands.push(Command::OpenAddSurvey);
        }
        if ui
            .button("Add survey from photos…")
            .on_hover_text(
                "A later survey's photos, registered by COLMAP into the twin's posed survey                  (as `twin add-survey --photos --align colmap`)",
            )
            .clicked()
        {
            commands.push(Command::OpenAddSurveyFromPhotos);
        }
        ui.separator();
        let later = current > 0;
        if ui
            .add_enabled(later, egui::Button::new("Detect changes"))
            .on_hover_text(
                "Render the twin before this survey at its poses: damage in its masks the twin \
                 does not show is new",
            )
            .clicked()
        {
            commands.push(Command::DetectChanges);
        }
        ui.separator();
        egui::ComboBox::from_id_salt("timeline-strategy")
            .selected_text(format!("{:?}", self.strategy).to_lowercase())
            .show_ui(ui, |ui| {
                for s in [Strategy::Finetune, Strategy::Retrain] {
                    ui.selectable_value(&mut self.strategy, s, format!("{s:?}").to_lowercase());
                }
            });
        ui.add(
            egui::DragValue::new(&mut self.iterations)
                .range(10..=30_000)
                .suffix(" steps"),
        );
        if ui
            .add_enabled(later, egui::Button::new("Update twin"))
            .on_hover_text(
                "Refine the twin before this survey with its photos and masks; writes this \
                 survey's model, earlier ones stay",
            )
            .clicked()
        {
            commands.push(Command::UpdateTwin {
                strategy: self.strategy,
                iterations: self.iterations,
            });
        }
    }
}

/// The surveys by date (click one, or < >, to show the twin as of it).
fn survey_strip(ui: &mut egui::Ui, timeline: &TimelineView, commands: &mut Vec<Command>) {
    let surveys = &timeline.twin.project.surveys;
    let current = timeline.current;
    ui.strong("Surveys");
    if ui
        .add_enabled(current > 0, egui::Button::new("<"))
        .on_hover_text("The survey before")
        .clicked()
    {
        commands.push(Command::ShowSurvey(current - 1));
    }
    for (i, survey) in surveys.iter().enumerate() {
        let mut text = format!("{}  {}", survey.name, survey.date);
        if survey.changes.is_some() {
            text.push_str("  Δ");
        }
        let loading = timeline.loading.contains(&i);
        if loading {
            text.push_str("  …");
        }
        let label = egui::RichText::new(text);
        let label = if survey.model.is_none() {
            label.weak()
        } else {
            label
        };
        let hover = match (&survey.model, &survey.changes) {
            (None, _) => "No model yet: update the twin with this survey",
            (Some(_), Some(_)) => "The twin as of this survey (changes detected: Δ)",
            (Some(_), None) => "The twin as of this survey",
        };
        if ui
            .selectable_label(i == current, label)
            .on_hover_text(hover)
            .clicked()
        {
            commands.push(Command::ShowSurvey(i));
        }
    }
    if ui
        .add_enabled(current + 1 < surveys.len(), egui::Button::new(">"))
        .on_hover_text("The survey after")
        .clicked()
    {
        commands.push(Command::ShowSurvey(current + 1));
    }
}

/// The survey compared with the one shown and how (side by side or swipe), damage coloured by
/// survey, and the change maps.
fn compare_controls(
    ui: &mut egui::Ui,
    timeline: &TimelineView,
    state: &AppState,
    commands: &mut Vec<Command>,
) {
    let surveys = &timeline.twin.project.surveys;
    let current = timeline.current;
    let name = |i: Option<usize>| {
        i.and_then(|i| surveys.get(i))
            .map_or("nothing".to_string(), |s| s.name.clone())
    };
    let mut compare = timeline.compare;
    egui::ComboBox::from_id_salt("timeline-compare")
        .selected_text(format!("compare with {}", name(compare)))
        .show_ui(ui, |ui| {
            ui.selectable_value(&mut compare, None, "nothing");
            for (i, s) in surveys.iter().enumerate() {
                if i != current && s.model.is_some() {
                    ui.selectable_value(&mut compare, Some(i), &s.name);
                }
            }
        });
    if compare != timeline.compare {
        commands.push(Command::CompareSurvey(compare));
    }
    ui.add_enabled_ui(timeline.compare.is_some(), |ui| {
        let mut layout = state.settings.survey_layout;
        ui.selectable_value(&mut layout, SurveyLayout::SideBySide, "side by side");
        ui.selectable_value(&mut layout, SurveyLayout::Swipe, "swipe");
        if layout != state.settings.survey_layout {
            edit_settings(state, commands, |s| s.survey_layout = layout);
        }
    });
    let mut by_survey = state.settings.damage.by_survey;
    if ui
        .checkbox(&mut by_survey, "damage by survey")
        .on_hover_text(
            "Earlier surveys' damage in blue, the latest shown survey's in the new-damage colour",
        )
        .changed()
    {
        edit_settings(state, commands, |s| {
            s.damage.by_survey = by_survey;
            s.damage.enabled |= by_survey;
        });
    }
    let has_changes = surveys.get(current).is_some_and(|s| s.changes.is_some());
    let mut maps = timeline.show_change_maps;
    if ui
        .add_enabled(has_changes, egui::Checkbox::new(&mut maps, "change maps"))
        .on_hover_text("Snapping to a survey view shows its change map instead of its photo")
        .changed()
    {
        commands.push(Command::ShowChangeMaps(maps));
    }
}

/// A running timeline job's progress and its cancel button.
fn job_progress(ui: &mut egui::Ui, job: &TimelineJob, commands: &mut Vec<Command>) {
    let (fraction, text) = match &job.progress {
        Some(p) => (
            p.step as f32 / p.total.max(1) as f32,
            format!(
                "{}: {} {}/{} · {:.0} s left",
                job.name(),
                p.phase,
                p.step,
                p.total,
                p.eta.as_secs_f32()
            ),
        ),
        None => (0.0, format!("{}…", job.name())),
    };
    ui.add(
        egui::ProgressBar::new(fraction)
            .text(text)
            .desired_width(360.0),
    );
    if ui.button("Cancel").clicked() {
        commands.push(Command::CancelTimelineJob);
    }
}
