//! Selection: the count, selecting by damage (class above a probability, optionally first seen in
//! one survey), marking or clearing a damage class on the selection by hand, refining the
//! selection, hide and undo. The drawing tools are keys in the viewport (listed here).

use crate::app::commands::Command;
use crate::app::panels::edit_settings;
use crate::app::state::{AppState, RefineSession};
use crate::damage::DamageClass;
use crate::damage::refine::Strategy;
use crate::splats::Splats;
use crate::splats::model::NO_SURVEY;
use crate::splats::selection::{SetOp, selected_count};

pub struct SelectionPanel {
    strategy: Strategy,
    iterations: u32,
    class: DamageClass,
    threshold: f32,
    /// None: any survey.
    survey: Option<u16>,
}

impl Default for SelectionPanel {
    fn default() -> Self {
        SelectionPanel {
            strategy: Strategy::Finetune,
            iterations: 300,
            class: DamageClass::Crack,
            threshold: 0.5,
            survey: None,
        }
    }
}

impl SelectionPanel {
    pub fn ui(&mut self, ui: &mut egui::Ui, state: &AppState, commands: &mut Vec<Command>) {
        let Some(splats) = &state.splats else {
            ui.weak("No model.");
            return;
        };
        ui.label(format!(
            "{} of {} Gaussians selected",
            selected_count(splats),
            splats.len()
        ));
        ui.weak(
            "R rectangle · L lasso · P polygon · B brush · C click · I eyedropper · O sphere · \
             X box · M measure · F frames the selection · Esc leaves; Shift adds, Ctrl removes",
        );
        tool_settings(ui, state, commands);
        if let Some(text) = state.distance_text() {
            ui.horizontal(|ui| {
                ui.label(format!("Distance: {text}"));
                if ui.small_button("Clear").clicked() {
                    commands.push(Command::ClearDistance);
                }
            });
        }
        self.damage_choice(ui, splats);
        self.damage_buttons(ui, state, commands);
        edit_buttons(ui, commands);
        ui.separator();
        match &state.refine {
            Some(session) => refine_progress(ui, session, commands),
            None => self.refine_controls(ui, splats, state, commands),
        }
        undo_buttons(ui, state, commands);
    }

    /// The damage class and probability to select by, and the survey it was first seen in.
    fn damage_choice(&mut self, ui: &mut egui::Ui, splats: &Splats) {
        ui.horizontal(|ui| {
            egui::ComboBox::from_id_salt("selection-class")
                .selected_text(self.class.id())
                .show_ui(ui, |ui| {
                    for class in DamageClass::ALL {
                        ui.selectable_value(&mut self.class, class, class.id());
                    }
                });
            ui.add(egui::Slider::new(&mut self.threshold, 0.05..=0.95).text("p ≥"));
        });
        let mut surveys: Vec<u16> = splats
            .meta
            .damage_survey
            .iter()
            .copied()
            .filter(|&s| s != NO_SURVEY)
            .collect();
        surveys.sort_unstable();
        surveys.dedup();
        ui.horizontal(|ui| {
            ui.label("First seen in");
            let label = |s: Option<u16>| {
                s.map_or("any survey".to_string(), |s| format!("survey {}", s + 1))
            };
            egui::ComboBox::from_id_salt("selection-survey")
                .selected_text(label(self.survey))
                .show_ui(ui, |ui| {
                    ui.selectable_value(&mut self.survey, None, label(None));
                    for &s in &surveys {
                        ui.selectable_value(&mut self.survey, Some(s), label(Some(s)));
                    }
                });
        });
    }

    /// Selecting the chosen damage (by probability, or from the snapped view's mask) and
    /// marking or clearing its class on the selection by hand.
    fn damage_buttons(&self, ui: &mut egui::Ui, state: &AppState, commands: &mut Vec<Command>) {
        ui.horizontal(|ui| {
            for (text, op) in [("Select damage", SetOp::Set), ("Add", SetOp::Add)] {
                if ui.button(text).clicked() {
                    commands.push(Command::SelectDamage {
                        class: self.class,
                        threshold: self.threshold,
                        survey: self.survey,
                        op,
                    });
                }
            }
            if ui
                .add_enabled(state.snap.is_some(), egui::Button::new("From mask"))
                .on_hover_text(
                    "The snapped view's mask of this class, lifted to the Gaussians that draw it",
                )
                .clicked()
            {
                commands.push(Command::SelectFromMask {
                    class: self.class,
                    op: SetOp::Set,
                });
            }
        });
        ui.horizontal(|ui| {
            if ui
                .button(format!("Mark {}", self.class.id()))
                .on_hover_text("Set this damage class on the selection (saved in the PLY)")
                .clicked()
            {
                commands.push(Command::SetDamageClass {
                    class: self.class,
                    on: true,
                });
            }
            if ui.button(format!("Clear {}", self.class.id())).clicked() {
                commands.push(Command::SetDamageClass {
                    class: self.class,
                    on: false,
                });
            }
        });
    }

    /// The refinement's strategy and steps, and the button that refines the selection (with a
    /// dataset to refine on and something selected).
    fn refine_controls(
        &mut self,
        ui: &mut egui::Ui,
        splats: &Splats,
        state: &AppState,
        commands: &mut Vec<Command>,
    ) {
        ui.horizontal(|ui| {
            egui::ComboBox::from_id_salt("refine-strategy")
                .selected_text(format!("{:?}", self.strategy).to_lowercase())
                .show_ui(ui, |ui| {
                    for s in [Strategy::Finetune, Strategy::Retrain] {
                        let name = format!("{s:?}").to_lowercase();
                        ui.selectable_value(&mut self.strategy, s, name);
                    }
                });
            ui.add(
                egui::DragValue::new(&mut self.iterations)
                    .range(10..=20_000)
                    .suffix(" steps"),
            );
        });
        let can =
            selected_count(splats) > 0 && state.scene.as_ref().is_some_and(|s| s.dataset.is_some());
        if ui
            .add_enabled(can, egui::Button::new("Refine selection"))
            .on_hover_text(
                "Train the selected Gaussians on the full-resolution photos inside their \
                 hulls, the rest frozen (undo restores the model)",
            )
            .clicked()
        {
            commands.push(Command::RefineSelection {
                strategy: self.strategy,
                iterations: self.iterations,
            });
        }
    }
}

/// The selection tools' settings: front-most only, the eyedropper's colour match and the
/// sphere and box radius (one settings update when any changed).
fn tool_settings(ui: &mut egui::Ui, state: &AppState, commands: &mut Vec<Command>) {
    let settings = &state.settings;
    let mut front = settings.selection_front_most;
    let mut colour = settings.colour_match;
    let mut radius = settings.volume_radius;
    ui.checkbox(&mut front, "front-most only").on_hover_text(
        "Shapes take only the Gaussians that draw inside them (not those hidden behind)",
    );
    ui.add(egui::Slider::new(&mut colour, 0.01..=0.5).text("colour match"));
    ui.add(
        egui::Slider::new(&mut radius, 0.01..=20.0)
            .logarithmic(true)
            .text("volume radius"),
    );
    if (front, colour, radius)
        != (
            settings.selection_front_most,
            settings.colour_match,
            settings.volume_radius,
        )
    {
        edit_settings(state, commands, |s| {
            s.selection_front_most = front;
            s.colour_match = colour;
            s.volume_radius = radius;
        });
    }
}

/// Select all or none, invert, hide and unhide.
fn edit_buttons(ui: &mut egui::Ui, commands: &mut Vec<Command>) {
    ui.horizontal(|ui| {
        for (text, command) in [
            ("All", Command::SelectAll),
            ("None", Command::SelectNone),
            ("Invert", Command::InvertSelection),
            ("Hide", Command::HideSelected),
            ("Unhide", Command::UnhideAll),
        ] {
            if ui.small_button(text).clicked() {
                commands.push(command);
            }
        }
    });
}

/// A running refinement's phase and step, and its cancel button.
fn refine_progress(ui: &mut egui::Ui, session: &RefineSession, commands: &mut Vec<Command>) {
    ui.horizontal(|ui| {
        let text = session
            .progress
            .as_ref()
            .map_or("starting".to_string(), |p| {
                format!("{} {} / {}", p.phase, p.step, p.total)
            });
        ui.spinner();
        ui.label(format!("refining: {text}"));
        if ui.button("Cancel").clicked() {
            commands.push(Command::CancelRefine);
        }
    });
}

/// Undo and redo of selection, visibility and damage-class edits.
fn undo_buttons(ui: &mut egui::Ui, state: &AppState, commands: &mut Vec<Command>) {
    ui.horizontal(|ui| {
        if ui
            .add_enabled(state.edits.can_undo(), egui::Button::new("Undo"))
            .clicked()
        {
            commands.push(Command::Undo);
        }
        if ui
            .add_enabled(state.edits.can_redo(), egui::Button::new("Redo"))
            .clicked()
        {
            commands.push(Command::Redo);
        }
    });
}
