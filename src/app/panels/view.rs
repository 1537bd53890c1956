//! View settings: navigation mode, field of view, splat scale, background, grid and frusta,
//! adaptive resolution, photo comparison, and the damage layer (issue 7: opacity, damage-only,
//! per-class toggles and colours). Reads the state, queues commands.

use crate::app::camera_controller::NavMode;
use crate::app::commands::Command;
use crate::app::panels::edit_settings;
use crate::app::photo_damage::PhotoDamage;
use crate::app::settings::{CompareMode, ViewportRenderer};
use crate::app::state::AppState;
use crate::damage::DamageClass;

#[derive(Default)]
pub struct ViewPanel;

impl ViewPanel {
    pub fn ui(&mut self, ui: &mut egui::Ui, state: &AppState, commands: &mut Vec<Command>) {
        edit_settings(state, commands, |s| {
            egui::Grid::new("view-settings").num_columns(2).show(ui, |ui| {
                ui.label("Navigation");
                ui.horizontal(|ui| {
                    ui.selectable_value(&mut s.nav_mode, NavMode::Orbit, "Orbit")
                        .on_hover_text("Drag: orbit · right/middle drag: pan · scroll: zoom · WASD/QE: move");
                    ui.selectable_value(&mut s.nav_mode, NavMode::Fly, "Fly")
                        .on_hover_text("Drag: look around · WASD/QE: fly · Shift: faster");
                });
                ui.end_row();
                ui.label("Field of view");
                ui.add(egui::Slider::new(&mut s.fov_deg, 20.0..=100.0).suffix("°"));
                ui.end_row();
                ui.label("Fly speed");
                ui.add(egui::Slider::new(&mut s.fly_speed, 0.05..=10.0).logarithmic(true));
                ui.end_row();
                ui.label("Splat scale");
                ui.add(egui::Slider::new(&mut s.splat_scale, 0.05..=2.0));
                ui.end_row();
                ui.label("Background");
                ui.color_edit_button_rgb(&mut s.background);
                ui.end_row();
                ui.label("Overlays");
                ui.horizontal(|ui| {
                    ui.checkbox(&mut s.show_grid, "grid");
                    ui.checkbox(&mut s.show_frusta, "cameras");
                    ui.checkbox(&mut s.turntable, "turntable");
                });
                ui.end_row();
                ui.label("Renderer");
                ui.horizontal(|ui| {
                    ui.selectable_value(&mut s.viewport_renderer, ViewportRenderer::Auto, "auto")
                        .on_hover_text("GPU pass on a graphics card, CPU worker on a software driver");
                    ui.selectable_value(&mut s.viewport_renderer, ViewportRenderer::Gpu, "GPU");
                    ui.selectable_value(&mut s.viewport_renderer, ViewportRenderer::Cpu, "CPU")
                        .on_hover_text("CPU reference rasterizer on a worker thread: never holds up the panels");
                });
                ui.end_row();
                ui.label("Adaptive resolution");
                ui.checkbox(&mut s.adaptive_resolution, "")
                    .on_hover_text("Render fewer pixels while the camera moves");
                ui.end_row();
                if s.adaptive_resolution {
                    ui.label("Target frame");
                    ui.add(egui::Slider::new(&mut s.target_frame_ms, 10.0..=200.0).suffix(" ms"));
                    ui.end_row();
                }
                ui.label("Photo comparison");
                ui.horizontal(|ui| {
                    ui.selectable_value(&mut s.compare_mode, CompareMode::Swipe, "swipe");
                    ui.selectable_value(&mut s.compare_mode, CompareMode::Blend, "blend");
                    ui.selectable_value(&mut s.compare_mode, CompareMode::SideBySide, "side by side");
                });
                ui.end_row();
                if s.compare_mode == CompareMode::Blend {
                    ui.label("Photo opacity");
                    ui.add(egui::Slider::new(&mut s.compare_blend, 0.0..=1.0));
                    ui.end_row();
                }
                ui.label("Ignore masks");
                ui.checkbox(&mut s.show_ignore_masks, "")
                    .on_hover_text("Dim the parts of a photo its ignore mask keeps out of training");
                ui.end_row();
                ui.label("Damage on photo");
                ui.horizontal(|ui| {
                    ui.selectable_value(&mut s.photo_damage, PhotoDamage::Off, "off");
                    ui.selectable_value(&mut s.photo_damage, PhotoDamage::Masks, "masks")
                        .on_hover_text("The view's damage masks, as training reads them");
                    ui.selectable_value(&mut s.photo_damage, PhotoDamage::Probabilities, "probabilities")
                        .on_hover_text("The segmenter's probabilities (probabilities/<class>/), else the masks");
                });
                ui.end_row();
            });
            ui.collapsing("Damage layer", |ui| {
                let d = &mut s.damage;
                ui.checkbox(&mut d.enabled, "show damage");
                ui.add_enabled_ui(d.enabled, |ui| {
                    ui.add(egui::Slider::new(&mut d.opacity, 0.0..=1.0).text("opacity"));
                    ui.checkbox(&mut d.damage_only, "damage only");
                    for (k, class) in DamageClass::ALL.iter().enumerate() {
                        ui.horizontal(|ui| {
                            ui.checkbox(&mut d.visible[k], class.id());
                            ui.color_edit_button_srgb(&mut d.colours[k]);
                        });
                    }
                });
            });
        });
        ui.horizontal(|ui| {
            if ui.button("Reset view").clicked() {
                commands.push(Command::ResetView);
            }
            if state.snap.is_some() && ui.button("Leave camera").clicked() {
                commands.push(Command::Unsnap);
            }
        });
    }
}
