//! Live charts with egui_plot: training loss, held-out PSNR and Gaussian count against wall time.
//! Read-only.

use egui_plot::{Line, Plot, PlotPoints, Points};

use crate::app::commands::Command;
use crate::app::state::AppState;

#[derive(Default)]
pub struct ChartsPanel;

fn chart(ui: &mut egui::Ui, id: &str, height: f32, add: impl FnOnce(&mut egui_plot::PlotUi<'_>)) {
    Plot::new(id)
        .height(height)
        .allow_scroll(false)
        .allow_zoom(false)
        .allow_drag(false)
        .show_axes([true, true])
        .x_axis_label("s")
        .show(ui, add);
}

impl ChartsPanel {
    pub fn ui(&mut self, ui: &mut egui::Ui, state: &AppState, _commands: &mut Vec<Command>) {
        let history = &state.history;
        if history.samples.is_empty() {
            ui.weak("Charts appear when training starts.");
            return;
        }
        let height = ((ui.available_height() - 60.0) / 3.0).clamp(60.0, 160.0);
        ui.label("Loss");
        let loss = history.series(|s| s.loss);
        chart(ui, "chart-loss", height, |plot| {
            plot.line(Line::new("loss", PlotPoints::from(loss)));
        });
        ui.label("Held-out PSNR (dB)");
        let psnr: Vec<[f64; 2]> = history
            .evals
            .iter()
            .filter(|e| e.psnr.is_finite())
            .map(|e| [e.wall_s, e.psnr])
            .collect();
        chart(ui, "chart-psnr", height, |plot| {
            plot.line(Line::new("PSNR", PlotPoints::from(psnr.clone())));
            plot.points(Points::new("PSNR points", PlotPoints::from(psnr)).radius(3.0));
        });
        ui.label("Gaussians");
        let count = history.series(|s| s.gaussians as f64);
        chart(ui, "chart-gaussians", height, |plot| {
            plot.line(Line::new("Gaussians", PlotPoints::from(count)));
        });
    }
}
