//! Drawing the splats: one picture, or two when a second survey is compared with the one shown
//! (side by side, or one over the other split by a swipe handle), both from the same camera so
//! that orbiting one moves the other. Each picture has its own renderer slot: a GPU paint
//! callback or a CPU worker.

use std::sync::Arc;

use super::navigation::FrameView;
use super::{FramePlan, Viewport};
use crate::app::cpu_view::ViewRequest;
use crate::app::state::AppState;
use crate::damage::layer::DamageLayer;
use crate::scene::Camera;
use crate::splats::Splats;

/// A model and how to draw it.
pub(super) struct Picture<'a> {
    pub splats: &'a Arc<Splats>,
    /// Bumped whenever `splats` changes.
    pub generation: u64,
    pub layer: &'a DamageLayer,
}

impl Viewport {
    /// Draws the model shown and, when a survey is compared, its model too (beside it or under
    /// the swipe handle) with both surveys' names; without a model, says why. Returns true when
    /// a GPU render was queued this frame.
    pub(super) fn draw_models(
        &mut self,
        ui: &egui::Ui,
        painter: &egui::Painter,
        plan: &FramePlan,
        camera: &Camera,
        view: &FrameView,
        state: &AppState,
    ) -> bool {
        let Some(splats) = &state.splats else {
            if view.snap.is_none() {
                painter.text(
                    plan.full.center(),
                    egui::Align2::CENTER_CENTER,
                    if state.timeline.is_some() {
                        "this survey has no model yet: Update twin makes it from the one before"
                    } else if state.scene.is_some() {
                        "waiting for the first model…"
                    } else {
                        "Open a dataset or drop a folder here"
                    },
                    egui::FontId::proportional(16.0),
                    egui::Color32::GRAY,
                );
            }
            return false;
        };
        let (full, render_rect) = (plan.full, plan.render_rect);
        let layer = match &state.timeline {
            Some(t) => t.layer(&state.settings.damage, t.current),
            None => state.settings.damage.clone(),
        };
        let shown = Picture {
            splats,
            generation: state.splats_generation,
            layer: &layer,
        };
        let mut rendered = self.draw_picture(
            painter,
            0,
            render_rect,
            render_rect,
            camera,
            &shown,
            state,
            plan.use_cpu,
        );
        if let (Some((index, other)), Some(t)) = (&plan.compared, &state.timeline) {
            let layer = t.layer(&state.settings.damage, *index);
            let other = Picture {
                splats: other,
                generation: t.compare_generation,
                layer: &layer,
            };
            let (rect, clip) = if plan.side_by_side {
                let left = full.split_left_right_at_fraction(0.5).0;
                (left, left)
            } else {
                let x = full.min.x + self.survey_swipe() * full.width();
                (
                    full,
                    egui::Rect::from_min_max(full.min, egui::pos2(x, full.max.y)),
                )
            };
            rendered |=
                self.draw_picture(painter, 1, rect, clip, camera, &other, state, plan.use_cpu);
            self.draw_survey_labels(ui, painter, full, render_rect, *index, state);
        }
        rendered
    }

    /// Draws `picture` rendered at `camera`'s size, stretched over `rect` and shown only inside
    /// `clip`, in renderer slot `slot`. Returns true when a GPU render was queued this frame.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn draw_picture(
        &mut self,
        painter: &egui::Painter,
        slot: usize,
        rect: egui::Rect,
        clip: egui::Rect,
        camera: &Camera,
        picture: &Picture,
        state: &AppState,
        use_cpu: bool,
    ) -> bool {
        let settings = &state.settings;
        match self.cpu_views.get_mut(slot) {
            Some(Some(Ok(view))) if use_cpu => {
                view.request(
                    ViewRequest {
                        generation: picture.generation,
                        camera: *camera,
                        splat_scale: settings.splat_scale,
                        damage: picture.layer.clone(),
                        background: settings.background,
                    },
                    picture.splats,
                );
                if let Some(texture) = view.texture() {
                    painter.image(texture.id(), clip, uv_of(rect, clip), egui::Color32::WHITE);
                }
                false
            }
            _ if use_cpu => false,
            _ => self.splat_view.paint(
                &painter.with_clip_rect(clip),
                slot,
                rect,
                camera,
                picture.splats,
                picture.generation,
                settings,
                picture.layer,
            ),
        }
    }

    /// Where the swipe handle between two surveys is, in [0, 1] of the viewport width.
    pub(super) fn survey_swipe(&mut self) -> f32 {
        if !(self.survey_swipe > 0.0 && self.survey_swipe <= 1.0) {
            self.survey_swipe = 0.5;
        }
        self.survey_swipe
    }

    /// Names the two surveys on screen (compared left, shown right) and, in swipe mode, draws
    /// the handle and lets it be dragged.
    pub(super) fn draw_survey_labels(
        &mut self,
        ui: &egui::Ui,
        painter: &egui::Painter,
        full: egui::Rect,
        render_rect: egui::Rect,
        compared: usize,
        state: &AppState,
    ) {
        let Some(timeline) = &state.timeline else {
            return;
        };
        let label = |index: usize| {
            timeline
                .twin
                .project
                .surveys
                .get(index)
                .map(|s| format!("{} · {}", s.name, s.date))
                .unwrap_or_default()
        };
        let font = egui::FontId::proportional(14.0);
        let colour = egui::Color32::WHITE;
        let side_by_side = render_rect != full;
        let (left_anchor, right_anchor) = if side_by_side {
            (full.left_bottom(), render_rect.left_bottom())
        } else {
            let x = full.min.x + self.survey_swipe() * full.width();
            let handle = egui::Rect::from_center_size(
                egui::pos2(x, full.center().y),
                egui::vec2(14.0, full.height()),
            );
            let response = ui.interact(
                handle,
                ui.scope_id().with("survey-swipe"),
                egui::Sense::drag(),
            );
            if response.dragged() {
                self.survey_swipe =
                    (self.survey_swipe + response.drag_delta().x / full.width()).clamp(0.02, 0.98);
            }
            painter.line_segment(
                [egui::pos2(x, full.min.y), egui::pos2(x, full.max.y)],
                egui::Stroke::new(2.0, colour),
            );
            painter.circle_filled(egui::pos2(x, full.center().y), 7.0, colour);
            (full.left_bottom(), egui::pos2(x, full.max.y))
        };
        if side_by_side {
            painter.line_segment(
                [render_rect.left_top(), render_rect.left_bottom()],
                egui::Stroke::new(2.0, egui::Color32::from_gray(40)),
            );
        }
        let offset = egui::vec2(8.0, -8.0);
        painter.text(
            left_anchor + offset,
            egui::Align2::LEFT_BOTTOM,
            label(compared),
            font.clone(),
            colour,
        );
        painter.text(
            right_anchor + offset,
            egui::Align2::LEFT_BOTTOM,
            label(timeline.current),
            font,
            colour,
        );
    }
}

/// The texture coordinates of the part `clip` of a picture stretched over `rect`.
fn uv_of(rect: egui::Rect, clip: egui::Rect) -> egui::Rect {
    let u = |x: f32| ((x - rect.min.x) / rect.width().max(1e-6)).clamp(0.0, 1.0);
    let v = |y: f32| ((y - rect.min.y) / rect.height().max(1e-6)).clamp(0.0, 1.0);
    egui::Rect::from_min_max(
        egui::pos2(u(clip.min.x), v(clip.min.y)),
        egui::pos2(u(clip.max.x), v(clip.max.y)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_left_part_of_a_picture_maps_to_the_left_texture_coordinates() {
        let rect = egui::Rect::from_min_size(egui::pos2(100.0, 50.0), egui::vec2(400.0, 200.0));
        let clip = egui::Rect::from_min_max(rect.min, egui::pos2(200.0, 250.0));
        let uv = uv_of(rect, clip);
        assert!((uv.min.x - 0.0).abs() < 1e-6 && (uv.max.x - 0.25).abs() < 1e-6);
        assert!((uv.min.y - 0.0).abs() < 1e-6 && (uv.max.y - 1.0).abs() < 1e-6);
        assert_eq!(
            uv_of(rect, rect),
            egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0))
        );
    }
}
