//! The log: the last lines from the viewer, the workers and the trainer. Read-only.

use crate::app::commands::Command;
use crate::app::state::AppState;

#[derive(Default)]
pub struct LogPanel;

impl LogPanel {
    pub fn ui(&mut self, ui: &mut egui::Ui, state: &AppState, _commands: &mut Vec<Command>) {
        egui::ScrollArea::vertical()
            .stick_to_bottom(true)
            .auto_shrink([false, true])
            .max_height(120.0)
            .show(ui, |ui| {
                for line in &state.log {
                    let text = egui::RichText::new(line).monospace().small();
                    if line.starts_with("error") || line.contains("failed") {
                        ui.colored_label(ui.visuals().error_fg_color, text);
                    } else {
                        ui.label(text);
                    }
                }
            });
    }
}
