//! Statistics: Gaussians, iteration, iterations per second, held-out PSNR, memory, and the
//! viewport's frame time and render scale. Read-only.

use crate::app::commands::Command;
use crate::app::state::AppState;

#[derive(Default)]
pub struct StatsPanel;

impl StatsPanel {
    pub fn ui(&mut self, ui: &mut egui::Ui, state: &AppState, _commands: &mut Vec<Command>) {
        egui::Grid::new("stats")
            .num_columns(2)
            .striped(true)
            .show(ui, |ui| {
                let row = |ui: &mut egui::Ui, name: &str, value: String| {
                    ui.label(name);
                    ui.monospace(value);
                    ui.end_row();
                };
                row(
                    ui,
                    "Gaussians",
                    state
                        .splats
                        .as_ref()
                        .map(|s| s.len().to_string())
                        .unwrap_or_else(|| "–".into()),
                );
                let progress = state.training.as_ref().and_then(|t| t.progress.as_ref());
                row(
                    ui,
                    "Iteration",
                    progress
                        .map(|p| format!("{} / {}", p.step, p.total))
                        .unwrap_or_else(|| "–".into()),
                );
                row(
                    ui,
                    "it/s",
                    state
                        .history
                        .iterations_per_second()
                        .map(|r| format!("{r:.1}"))
                        .unwrap_or_else(|| "–".into()),
                );
                row(
                    ui,
                    "Loss",
                    progress
                        .filter(|p| p.loss.is_finite())
                        .map(|p| format!("{:.4}", p.loss))
                        .unwrap_or_else(|| "–".into()),
                );
                row(
                    ui,
                    "Held-out PSNR",
                    state
                        .training
                        .as_ref()
                        .and_then(|t| t.heldout_psnr)
                        .map(|p| format!("{p:.2} dB"))
                        .unwrap_or_else(|| "–".into()),
                );
                row(
                    ui,
                    "Peak memory",
                    crate::metrics::peak_rss_mb()
                        .map(|m| format!("{m:.0} MB"))
                        .unwrap_or_else(|| "–".into()),
                );
                let f = &state.frame_stats;
                row(ui, "Frame", format!("{:.1} ms", f.frame_ms));
                row(
                    ui,
                    "Render",
                    format!(
                        "{}×{} ({:.0} %)",
                        f.render_size[0],
                        f.render_size[1],
                        f.render_scale * 100.0
                    ),
                );
            });
    }
}
