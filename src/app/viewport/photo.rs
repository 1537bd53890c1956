//! The photo comparison: the survey photo of the view the camera snapped to, side by side with
//! the render, blended over it or split by a swipe handle, its texture kept while the view and
//! photo stay the same.

use std::sync::Arc;

use super::Viewport;
use crate::app::cpu_view::color_image;
use crate::app::settings::CompareMode;
use crate::app::state::{AppState, Photo, Snap};
use crate::scene::RgbImage;

fn photo_texture(ctx: &egui::Context, image: &RgbImage) -> egui::TextureHandle {
    let pixels = color_image(image.width as usize, image.height as usize, &image.data);
    ctx.load_texture("survey-photo", pixels, egui::TextureOptions::LINEAR)
}

impl Viewport {
    /// The photo of `snap`'s view beside, over (blended) or swiped against the render, with the
    /// view's name on the render.
    pub(super) fn draw_photo(
        &mut self,
        ui: &mut egui::Ui,
        painter: &egui::Painter,
        render_rect: egui::Rect,
        photo_rect: egui::Rect,
        snap: &Snap,
        state: &AppState,
    ) {
        let image = match &snap.photo {
            Photo::Loaded(image) => image.clone(),
            Photo::Loading => {
                painter.text(
                    photo_rect.center_top() + egui::vec2(0.0, 16.0),
                    egui::Align2::CENTER_TOP,
                    "loading photo…",
                    egui::FontId::proportional(14.0),
                    egui::Color32::WHITE,
                );
                return;
            }
            Photo::Failed(e) => {
                painter.text(
                    photo_rect.center_top() + egui::vec2(0.0, 16.0),
                    egui::Align2::CENTER_TOP,
                    format!("photo: {e}"),
                    egui::FontId::proportional(14.0),
                    ui.visuals().error_fg_color,
                );
                return;
            }
        };
        let stale = self
            .photo
            .as_ref()
            .is_none_or(|(v, img, _)| *v != snap.view || !Arc::ptr_eq(img, &image));
        if stale {
            let texture = photo_texture(ui.ctx(), &image);
            self.photo = Some((snap.view, image.clone(), texture));
        }
        let Some((_, _, texture)) = &self.photo else {
            return;
        };
        let texture = texture.id();
        let full_uv = egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0));
        match state.settings.compare_mode {
            CompareMode::SideBySide => {
                painter.image(texture, photo_rect, full_uv, egui::Color32::WHITE);
            }
            CompareMode::Blend => {
                let alpha = (state.settings.compare_blend * 255.0) as u8;
                painter.image(
                    texture,
                    photo_rect,
                    full_uv,
                    egui::Color32::from_white_alpha(alpha),
                );
            }
            CompareMode::Swipe => self.draw_swiped_photo(ui, painter, texture, photo_rect),
        }
        draw_view_name(painter, render_rect, snap, state);
    }

    /// The photo's part left of the swipe handle over the render, and the handle, which can be
    /// dragged.
    fn draw_swiped_photo(
        &mut self,
        ui: &mut egui::Ui,
        painter: &egui::Painter,
        texture: egui::TextureId,
        photo_rect: egui::Rect,
    ) {
        if self.swipe <= 0.0 || self.swipe > 1.0 {
            self.swipe = 0.5;
        }
        let x = photo_rect.min.x + self.swipe * photo_rect.width();
        let left = egui::Rect::from_min_max(photo_rect.min, egui::pos2(x, photo_rect.max.y));
        let uv = egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(self.swipe, 1.0));
        painter.image(texture, left, uv, egui::Color32::WHITE);
        let handle = egui::Rect::from_center_size(
            egui::pos2(x, photo_rect.center().y),
            egui::vec2(12.0, photo_rect.height()),
        );
        let id = ui.scope_id().with("swipe-handle");
        let r = ui.interact(handle, id, egui::Sense::drag());
        if r.dragged() {
            self.swipe = (self.swipe + r.drag_delta().x / photo_rect.width()).clamp(0.01, 1.0);
        }
        painter.line_segment(
            [
                egui::pos2(x, photo_rect.min.y),
                egui::pos2(x, photo_rect.max.y),
            ],
            egui::Stroke::new(2.0, egui::Color32::WHITE),
        );
        painter.circle_filled(
            egui::pos2(x, photo_rect.center().y),
            6.0,
            egui::Color32::WHITE,
        );
    }
}

/// The snapped view's name and what its picture is (photo or change map), on the render.
fn draw_view_name(painter: &egui::Painter, render_rect: egui::Rect, snap: &Snap, state: &AppState) {
    let name = state
        .scene
        .as_ref()
        .and_then(|s| s.dataset.as_ref())
        .and_then(|d| d.views.get(snap.view))
        .map(|v| v.name.clone())
        .unwrap_or_default();
    painter.text(
        render_rect.left_top() + egui::vec2(8.0, 8.0),
        egui::Align2::LEFT_TOP,
        format!(
            "{name}: {} | render  (drag or scroll in the view to leave)",
            if snap.change_map {
                "change map"
            } else {
                "photo"
            }
        ),
        egui::FontId::proportional(13.0),
        egui::Color32::WHITE,
    );
}
