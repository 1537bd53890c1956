//! Training controls: start / pause / resume / stop, iterations, resolution scale, Gaussian
//! budget, mode and label weight, and a progress bar with ETA. Reads the state, queues commands.

use crate::app::commands::Command;
use crate::app::panels::edit_settings;
use crate::app::settings::TrainMode;
use crate::app::state::AppState;
use crate::app::training::{RunStatus, TrainingSession};
use crate::scene::ImageScale;

#[derive(Default)]
pub struct TrainingPanel;

/// `1:05` or `1:02:05`.
pub fn format_duration(seconds: f64) -> String {
    if !seconds.is_finite() || seconds < 0.0 {
        return "–".into();
    }
    let s = seconds.round() as u64;
    if s >= 3600 {
        format!("{}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60)
    } else {
        format!("{}:{:02}", s / 60, s % 60)
    }
}

impl TrainingPanel {
    pub fn ui(&mut self, ui: &mut egui::Ui, state: &AppState, commands: &mut Vec<Command>) {
        let session = state.training.as_ref();
        let running = session.is_some_and(|s| s.is_running());
        let can_train = state.scene.as_ref().is_some_and(|s| s.dataset.is_some());

        ui.add_enabled_ui(!running, |ui| {
            edit_settings(state, commands, |s| {
                let t = &mut s.training;
                egui::Grid::new("training-settings")
                    .num_columns(2)
                    .show(ui, |ui| {
                        ui.label("Iterations");
                        ui.add(
                            egui::DragValue::new(&mut t.iterations)
                                .range(1..=1_000_000)
                                .speed(50),
                        );
                        ui.end_row();
                        ui.label("Resolution");
                        egui::ComboBox::from_id_salt("training-resolution")
                            .selected_text(resolution_label(t.scale))
                            .show_ui(ui, |ui| {
                                for f in [1, 2, 4, 8] {
                                    let scale = ImageScale::Factor(f);
                                    ui.selectable_value(
                                        &mut t.scale,
                                        scale,
                                        resolution_label(scale),
                                    );
                                }
                            });
                        ui.end_row();
                        ui.label("Mode");
                        ui.horizontal(|ui| {
                            for mode in TrainMode::ALL {
                                ui.selectable_value(&mut t.mode, mode, mode.name());
                            }
                        });
                        ui.end_row();
                        ui.label("Gaussian budget")
                            .on_hover_text("Most Gaussians the model ends with (--budget)");
                        ui.horizontal(|ui| {
                            let mut on = t.budget.is_some();
                            ui.checkbox(&mut on, "");
                            let mut n = t.budget.unwrap_or(50_000);
                            ui.add_enabled(
                                on,
                                egui::DragValue::new(&mut n)
                                    .range(1..=10_000_000)
                                    .speed(100),
                            );
                            t.budget = on.then_some(n);
                        });
                        ui.end_row();
                        if t.mode == TrainMode::Label {
                            ui.label("Label weight");
                            ui.add(egui::Slider::new(&mut t.label_weight, 0.0..=2.0));
                            ui.end_row();
                        }
                    });
            });
        });

        run_buttons(ui, session, running, can_train, commands);

        let Some(session) = session else {
            if !can_train {
                ui.weak("Open a dataset to train.");
            }
            return;
        };
        ui.add(
            egui::ProgressBar::new(session.fraction())
                .text(progress_text(session))
                // Only while preparing, when there is no progress to show: an animated bar
                // repaints every frame, and on a software driver those frames took about a core
                // from training.
                .animate(session.status == RunStatus::Preparing),
        );
    }
}

/// Train, or pause / resume the run, and stop it.
fn run_buttons(
    ui: &mut egui::Ui,
    session: Option<&TrainingSession>,
    running: bool,
    can_train: bool,
    commands: &mut Vec<Command>,
) {
    ui.horizontal(|ui| {
        match session.map(|s| &s.status) {
            Some(RunStatus::Running) | Some(RunStatus::Preparing) => {
                if ui.button("Pause").clicked() {
                    commands.push(Command::PauseTraining);
                }
            }
            Some(RunStatus::Paused) => {
                if ui.button("Resume").clicked() {
                    commands.push(Command::ResumeTraining);
                }
            }
            _ => {
                if ui
                    .add_enabled(can_train, egui::Button::new("Train"))
                    .clicked()
                {
                    commands.push(Command::StartTraining);
                }
            }
        }
        if ui.add_enabled(running, egui::Button::new("Stop")).clicked() {
            commands.push(Command::StopTraining);
        }
    });
}

/// The run's state and steps with the time left (`paused · 1200 / 7000 · ETA 1:05`).
fn progress_text(session: &TrainingSession) -> String {
    let (text, eta) = match (&session.status, &session.progress) {
        (RunStatus::Preparing, _) => ("loading views…".to_string(), None),
        (RunStatus::Failed(e), _) => (format!("failed: {e}"), None),
        (
            RunStatus::Finished {
                cancelled, seconds, ..
            },
            _,
        ) => (
            format!(
                "{} in {}",
                if *cancelled { "stopped" } else { "done" },
                format_duration(*seconds)
            ),
            None,
        ),
        (status, Some(p)) => (
            format!(
                "{}{} / {}",
                if *status == RunStatus::Paused {
                    "paused · "
                } else {
                    ""
                },
                p.step,
                p.total
            ),
            Some(p.eta.as_secs_f64()),
        ),
        (_, None) => ("starting…".to_string(), None),
    };
    match eta {
        Some(eta) => format!("{text} · ETA {}", format_duration(eta)),
        None => text,
    }
}

/// A training scale as the panel names it: `1/4` for a factor, `960 px wide` for a width (a
/// width comes only from a project or settings file; the list offers factors).
fn resolution_label(scale: ImageScale) -> String {
    match scale {
        ImageScale::Factor(f) => format!("1/{f}"),
        ImageScale::Width(w) => format!("{w} px wide"),
    }
}

#[cfg(test)]
mod tests {
    use super::format_duration;

    #[test]
    fn durations_read_as_clock_times() {
        assert_eq!(format_duration(65.0), "1:05");
        assert_eq!(format_duration(3725.0), "1:02:05");
        assert_eq!(format_duration(f64::NAN), "–");
    }
}
