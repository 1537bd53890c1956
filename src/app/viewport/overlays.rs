//! The lines over the splats: the ground grid, the survey cameras' frusta (a click on one snaps
//! to that view) and the distance measurement, all drawn with the frame's camera from the
//! geometry in `app::overlay`.

use glam::Vec2;

use super::FramePlan;
use super::navigation::FrameView;
use crate::app::commands::Command;
use crate::app::overlay::{self, SegmentKind};
use crate::app::state::AppState;
use crate::scene::Camera;

/// Draws the grid, the frusta and the distance measurement over the render with `camera` (at
/// the render rectangle's point size), and over the compared survey's picture beside it.
pub(super) fn draw_overlays(
    painter: &egui::Painter,
    plan: &FramePlan,
    camera: &Camera,
    view: &FrameView,
    state: &AppState,
) {
    let render_rect = plan.render_rect;
    draw_overlays_in(
        &painter.with_clip_rect(render_rect),
        render_rect,
        camera,
        view,
        state,
    );
    if plan.compared.is_some() && plan.side_by_side {
        // The compared survey's picture has the same camera, grid and frusta.
        let left = plan.full.split_left_right_at_fraction(0.5).0;
        draw_overlays_in(&painter.with_clip_rect(left), left, camera, view, state);
    }
}

/// Draws the grid, the frusta (the snapped view's highlighted) and the distance measurement
/// over `rect`, whose top-left is `camera`'s pixel origin.
fn draw_overlays_in(
    painter: &egui::Painter,
    rect: egui::Rect,
    camera: &Camera,
    view: &FrameView,
    state: &AppState,
) {
    let Some(scene) = &state.scene else {
        return;
    };
    let mut segments = Vec::new();
    if state.settings.show_grid {
        segments.extend(overlay::grid(&scene.frame, 10));
    }
    if state.settings.show_frusta {
        let selected = view.snap.map(|s| s.view);
        let cameras = state.survey_cameras();
        segments.extend(overlay::frusta(
            &cameras,
            scene.frame.camera_distance * 0.08,
            selected,
        ));
    }
    let near = overlay::near_plane(&scene.frame);
    for seg in &segments {
        let Some((a, b)) = overlay::project_segment(camera, seg, near) else {
            continue;
        };
        let stroke = match seg.kind {
            SegmentKind::Grid => egui::Stroke::new(1.0, egui::Color32::from_gray(70)),
            SegmentKind::GridAxis => egui::Stroke::new(1.5, egui::Color32::from_gray(110)),
            SegmentKind::Frustum => egui::Stroke::new(1.0, egui::Color32::from_rgb(80, 170, 255)),
            SegmentKind::FrustumSelected => {
                egui::Stroke::new(2.0, egui::Color32::from_rgb(255, 200, 40))
            }
        };
        painter.line_segment(
            [
                rect.min + egui::vec2(a.x, a.y),
                rect.min + egui::vec2(b.x, b.y),
            ],
            stroke,
        );
    }
    draw_distance(painter, rect, camera, state);
}

/// The distance measurement: its points, the line between them and the distance.
fn draw_distance(painter: &egui::Painter, rect: egui::Rect, camera: &Camera, state: &AppState) {
    let colour = egui::Color32::from_rgb(255, 230, 0);
    let on_screen: Vec<egui::Pos2> = state
        .distance
        .iter()
        .filter_map(|&p| camera.project(p))
        .map(|p| rect.min + egui::vec2(p.x, p.y))
        .collect();
    for &p in &on_screen {
        painter.circle_filled(p, 4.0, colour);
    }
    if let [a, b] = on_screen.as_slice() {
        painter.line_segment([*a, *b], egui::Stroke::new(2.0, colour));
        if let Some(text) = state.distance_text() {
            painter.text(
                *b + egui::vec2(8.0, -8.0),
                egui::Align2::LEFT_BOTTOM,
                text,
                egui::FontId::proportional(14.0),
                colour,
            );
        }
    }
}

/// A click on a shown survey frustum (within 10 points) queues a snap to that view, unless the
/// view is snapped to already.
pub(super) fn snap_on_frustum_click(
    response: &egui::Response,
    render_rect: egui::Rect,
    camera: &Camera,
    view: &FrameView,
    state: &AppState,
    commands: &mut Vec<Command>,
) {
    if response.clicked()
        && let Some(pos) = response.interact_pointer_pos()
        && state.settings.show_frusta
        && let Some(scene) = &state.scene
    {
        let cameras = state.survey_cameras();
        let click = Vec2::new(pos.x - render_rect.min.x, pos.y - render_rect.min.y);
        let depth = scene.frame.camera_distance * 0.08;
        if let Some(i) = overlay::pick_frustum(
            camera,
            &cameras,
            depth,
            overlay::near_plane(&scene.frame),
            click,
            10.0,
        ) && view.snap.is_none_or(|s| s.view != i)
        {
            commands.push(Command::SnapToView(i));
        }
    }
}
