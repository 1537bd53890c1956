//! Damage regions: measure the model's damage (regions per class with lengths and areas, as the
//! report measures them) and list the regions; clicking one selects its Gaussians and frames it.

use crate::app::commands::Command;
use crate::app::state::AppState;
use crate::damage::DamageClass;

#[derive(Default)]
pub struct RegionsPanel;

impl RegionsPanel {
    pub fn ui(&mut self, ui: &mut egui::Ui, state: &AppState, commands: &mut Vec<Command>) {
        ui.horizontal(|ui| {
            let measure = ui
                .add_enabled(
                    state.splats.is_some() && !state.measuring,
                    egui::Button::new("Measure damage"),
                )
                .on_hover_text("Regions per class on the surface, with lengths and areas");
            if measure.clicked() {
                commands.push(Command::MeasureRegions);
            }
            if state.measuring {
                ui.spinner();
            }
            if let Some(r) = &state.regions
                && r.generation != state.splats_generation
            {
                ui.weak("(model changed since)");
            }
        });
        let Some(regions) = &state.regions else {
            return;
        };
        let m = &regions.measurement;
        ui.label(format!(
            "crack {:.2} m · spalling {:.2} m² · rebar {:.2} m",
            m.total_length(DamageClass::Crack),
            m.total_area(DamageClass::Spalling),
            m.total_length(DamageClass::Rebar),
        ));
        egui::ScrollArea::vertical()
            .max_height(240.0)
            .id_salt("regions")
            .show(ui, |ui| {
                let mut count = [0usize; 3];
                for (index, region) in m.regions.iter().enumerate() {
                    count[region.class.channel()] += 1;
                    let size = match region.length {
                        Some(l) => format!("{l:.2} m"),
                        None => format!("{:.3} m²", region.area),
                    };
                    let text = format!(
                        "{} {} · {size}",
                        region.class.id(),
                        count[region.class.channel()]
                    );
                    if ui.selectable_label(false, text).clicked() {
                        commands.push(Command::FocusRegion(index));
                    }
                }
            });
    }
}
