//! The 3D viewport: turns mouse and keys into camera input (orbit / pan / zoom, fly with
//! WASD/QE), picks the render resolution, draws the splats through the GPU paint callback, then
//! the grid, the survey frusta (click one to snap to it) and the photo comparison on top.
//! The camera is view state and changes here directly; everything else goes through commands.

mod photo;
mod pictures;

use std::sync::Arc;

use glam::{Vec2, Vec3};

use crate::app::camera_controller::CameraInput;
use crate::app::commands::Command;
use crate::app::cpu_view::CpuView;
use crate::app::frame_log::FrameLog;
use crate::app::overlay::{self, SegmentKind};
use crate::app::resolution::{AdaptiveResolution, FrameSample, scaled_size};
use crate::app::settings::ViewportRenderer;
use crate::app::settings::{CompareMode, SurveyLayout};
use crate::app::splat_view::{SLOTS, SplatView};
use crate::app::state::AppState;
use crate::app::tools::ToolState;
use crate::scene::{Camera, RgbImage};
use crate::splats::selection::SetOp;
use pictures::Picture;

/// Frame statistics the statistics panel shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameStats {
    pub frame_ms: f32,
    pub render_scale: f32,
    pub render_size: [u32; 2],
}

impl Default for FrameStats {
    fn default() -> Self {
        FrameStats {
            frame_ms: 0.0,
            render_scale: 1.0,
            render_size: [0, 0],
        }
    }
}

/// The viewport's own state between frames.
#[derive(Default)]
pub struct Viewport {
    resolution: AdaptiveResolution,
    splat_view: SplatView,
    photo: Option<(usize, Arc<RgbImage>, egui::TextureHandle)>,
    /// Swipe handle position in [0, 1] of the image width.
    swipe: f32,
    /// Where the viewport was laid out last frame, in points.
    rect: Option<egui::Rect>,
    frame_log: FrameLog,
    /// The last frame rendered splats (its time then measures the render).
    rendered_last_frame: bool,
    /// The CPU renderer's workers, one per picture, started on first use (software drivers, or
    /// by choice).
    cpu_views: [Option<Result<CpuView, String>>; SLOTS],
    /// Swipe handle between two surveys, in [0, 1] of the viewport width.
    survey_swipe: f32,
    /// The selection tool and the shape being drawn.
    pub tools: ToolState,
}

/// Reads navigation input for this frame (keys only when no text field has focus).
fn camera_input(ui: &egui::Ui, response: &egui::Response, viewport_height: f32) -> CameraInput {
    let mut input = CameraInput {
        viewport_height,
        ..CameraInput::default()
    };
    let keys_free = !ui.ctx().egui_wants_keyboard_input();
    ui.input(|i| {
        input.dt = i.stable_dt.min(0.1);
        if response.hovered() {
            input.zoom = i.smooth_scroll_delta.y;
        }
        if keys_free {
            let axis = |pos: egui::Key, neg: egui::Key| {
                f32::from(u8::from(i.key_down(pos))) - f32::from(u8::from(i.key_down(neg)))
            };
            input.fly = Vec3::new(
                axis(egui::Key::D, egui::Key::A),
                axis(egui::Key::E, egui::Key::Q),
                axis(egui::Key::W, egui::Key::S),
            );
            input.boost = i.modifiers.shift;
        }
    });
    let delta = response.drag_delta();
    let delta = Vec2::new(delta.x, delta.y);
    let pan_drag = response.dragged_by(egui::PointerButton::Secondary)
        || response.dragged_by(egui::PointerButton::Middle)
        || (response.dragged_by(egui::PointerButton::Primary) && ui.input(|i| i.modifiers.shift));
    if pan_drag {
        input.pan = delta;
    } else if response.dragged_by(egui::PointerButton::Primary) {
        input.rotate = delta;
    }
    input
}

/// The largest rectangle of aspect `w / h` centred in `rect`.
fn fit_aspect(rect: egui::Rect, w: f32, h: f32) -> egui::Rect {
    if !(w > 0.0 && h > 0.0) {
        return rect;
    }
    let scale = (rect.width() / w).min(rect.height() / h);
    egui::Rect::from_center_size(rect.center(), egui::vec2(w * scale, h * scale))
}

impl Viewport {
    /// Creates the GPU splat renderer on eframe's device (once; errors show in the viewport).
    pub fn install_renderer(&mut self, render_state: Option<&eframe::egui_wgpu::RenderState>) {
        self.splat_view.install(render_state);
    }

    /// Where the viewport was last laid out, in points (empty before the first frame).
    pub fn last_rect(&self) -> egui::Rect {
        self.rect.unwrap_or(egui::Rect::NOTHING)
    }

    /// The GPU renderer's last error, or why there is none (or why the CPU renderer could not
    /// start).
    pub fn renderer_error(&self) -> Option<String> {
        match self
            .cpu_views
            .iter()
            .flatten()
            .find_map(|v| v.as_ref().err())
        {
            Some(e) => Some(e.clone()),
            None => self.splat_view.error(),
        }
    }

    /// Whether the splats are drawn by the CPU worker rather than the GPU pass this frame.
    pub fn uses_cpu_renderer(&self, choice: ViewportRenderer) -> bool {
        match choice {
            ViewportRenderer::Gpu => false,
            ViewportRenderer::Cpu => true,
            ViewportRenderer::Auto => {
                self.splat_view.is_software() || !self.splat_view.is_available()
            }
        }
    }

    pub fn ui(&mut self, ui: &mut egui::Ui, state: &mut AppState, commands: &mut Vec<Command>) {
        let full = ui.available_rect_before_wrap();
        let response = ui.allocate_rect(full, egui::Sense::click_and_drag());
        self.rect = Some(full);
        let ppp = ui.ctx().pixels_per_point();
        let painter = ui.painter_at(full);
        let bg = state.settings.background;
        let bg32 = egui::Color32::from_rgb(
            (bg[0] * 255.0) as u8,
            (bg[1] * 255.0) as u8,
            (bg[2] * 255.0) as u8,
        );
        painter.rect_filled(full, 0.0, bg32);

        let mut input = camera_input(ui, &response, full.height());
        if self.tools.tool.is_some() && response.dragged_by(egui::PointerButton::Primary) {
            // The primary button draws the selection (Shift and Ctrl pick its set operation).
            input.rotate = Vec2::ZERO;
            input.pan = Vec2::ZERO;
        }
        if state.settings.turntable && state.snap.is_none() && input.rotate == Vec2::ZERO {
            // 0.35 rad/s about the up axis, expressed as the drag that would do it.
            input.rotate.x = -0.35 * input.dt / state.camera.rotate_speed;
        }
        if state.snap.is_some() && input.is_active() {
            // Navigating leaves the survey camera, continuing from its pose.
            if let Some(snap) = &state.snap {
                state.camera.snap_to(&snap.camera);
            }
            state.snap = None;
        }
        if state.snap.is_none() {
            state.camera.update(&input);
        } else {
            input = CameraInput::default();
        }

        // Where the render goes: the whole viewport, or the snapped camera's aspect (and only
        // the right half side by side).
        let snap_aspect = state.snap.as_ref().map(|s| {
            let k = s.camera.intrinsics;
            (k.width as f32, k.height as f32)
        });
        let compare = state.settings.compare_mode;
        // A second survey beside the one shown (not while looking through a survey camera).
        let compared = state
            .timeline
            .as_ref()
            .filter(|_| state.snap.is_none())
            .and_then(|t| t.compared());
        let side_by_side = state.settings.survey_layout == SurveyLayout::SideBySide;
        let (render_rect, photo_rect) = match snap_aspect {
            Some((w, h)) if compare == CompareMode::SideBySide => {
                let (left, right) = full.split_left_right_at_fraction(0.5);
                (fit_aspect(right, w, h), Some(fit_aspect(left, w, h)))
            }
            Some((w, h)) => {
                let r = fit_aspect(full, w, h);
                (r, Some(r))
            }
            None if compared.is_some() && side_by_side => {
                (full.split_left_right_at_fraction(0.5).1, None)
            }
            None => (full, None),
        };

        let frame_ms = ui.input(|i| i.unstable_dt) * 1000.0;
        let moving = input.is_active() || state.camera.is_moving();
        let use_cpu = self.uses_cpu_renderer(state.settings.viewport_renderer);
        let pictures = if compared.is_some() { 2 } else { 1 };
        if use_cpu {
            for view in self.cpu_views.iter_mut().take(pictures) {
                if view.is_none() {
                    *view = Some(CpuView::start(ui.ctx()));
                }
            }
        }
        // The CPU workers' pictures arrive between frames and carry their own render time: the
        // UI frames around them say nothing about what a render costs.
        let received: Option<f32> = if use_cpu {
            self.cpu_views
                .iter_mut()
                .take(pictures)
                .filter_map(|v| match v {
                    Some(Ok(view)) => view.receive(ui.ctx()),
                    _ => None,
                })
                .reduce(f32::max)
        } else {
            None
        };
        let (sample_ms, sample_rendered) = match received {
            Some(render_ms) => (render_ms, true),
            None if use_cpu => (frame_ms, false),
            None => (frame_ms, self.rendered_last_frame),
        };
        // While training streams new models, every snapshot is a render: keep those within
        // the budget too, or a resting camera would render each one at full resolution.
        let training = state.training.as_ref().is_some_and(|t| t.is_streaming());
        let scale = if state.settings.adaptive_resolution {
            self.resolution.update(
                FrameSample {
                    changing: moving || training,
                    frame_ms: sample_ms,
                    last_frame_rendered: sample_rendered,
                },
                state.settings.target_frame_ms,
                state.settings.min_render_scale,
            )
        } else {
            1.0
        };
        let px_w = (render_rect.width() * ppp).round().max(1.0) as u32;
        let px_h = (render_rect.height() * ppp).round().max(1.0) as u32;
        state.viewport_pixels = [px_w, px_h];
        let (rw, rh) = scaled_size(px_w, px_h, scale);
        let camera = state.view_camera(rw, rh);
        self.frame_log
            .record(ui.ctx(), frame_ms, scale, self.rendered_last_frame);
        if sample_rendered && use_cpu {
            self.frame_log.record_render(sample_ms);
        }
        state.frame_stats = FrameStats {
            frame_ms: self.resolution.frame_ms(),
            render_scale: scale,
            render_size: [rw, rh],
        };

        self.rendered_last_frame = false;
        if let Some(splats) = &state.splats {
            let layer = match &state.timeline {
                Some(t) => t.layer(&state.settings.damage, t.current),
                None => state.settings.damage.clone(),
            };
            let shown = Picture {
                splats,
                generation: state.splats_generation,
                layer: &layer,
            };
            self.rendered_last_frame = self.draw_picture(
                &painter,
                0,
                render_rect,
                render_rect,
                &camera,
                &shown,
                state,
                use_cpu,
            );
            if let (Some((index, other)), Some(t)) = (&compared, &state.timeline) {
                let layer = t.layer(&state.settings.damage, *index);
                let other = Picture {
                    splats: other,
                    generation: t.compare_generation,
                    layer: &layer,
                };
                let (rect, clip) = if side_by_side {
                    let left = full.split_left_right_at_fraction(0.5).0;
                    (left, left)
                } else {
                    let x = full.min.x + self.survey_swipe() * full.width();
                    (
                        full,
                        egui::Rect::from_min_max(full.min, egui::pos2(x, full.max.y)),
                    )
                };
                self.rendered_last_frame |=
                    self.draw_picture(&painter, 1, rect, clip, &camera, &other, state, use_cpu);
                self.draw_survey_labels(ui, &painter, full, render_rect, *index, state);
            }
        } else if state.snap.is_none() {
            painter.text(
                full.center(),
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
        if let Some(e) = self.splat_view.error() {
            painter.text(
                full.left_bottom() + egui::vec2(8.0, -8.0),
                egui::Align2::LEFT_BOTTOM,
                e,
                egui::FontId::proportional(12.0),
                ui.visuals().error_fg_color,
            );
        }

        // Overlays are drawn with the camera at the render rectangle's point size.
        let overlay_camera = state.view_camera(
            render_rect.width().max(1.0) as u32,
            render_rect.height().max(1.0) as u32,
        );
        self.draw_overlays(
            &painter.with_clip_rect(render_rect),
            render_rect,
            &overlay_camera,
            state,
        );
        if compared.is_some() && side_by_side {
            // The compared survey's picture has the same camera, grid and frusta.
            let left = full.split_left_right_at_fraction(0.5).0;
            self.draw_overlays(&painter.with_clip_rect(left), left, &overlay_camera, state);
        }
        self.tools.keys(ui.ctx(), &overlay_camera, commands);
        let op = ui.input(|i| SetOp::from_modifiers(i.modifiers.shift, i.modifiers.command));
        let tool_used =
            self.tools
                .pointer(&response, render_rect.min, &overlay_camera, op, commands);
        self.tools
            .draw(&painter, render_rect.min, response.hover_pos());
        if let Some(tool) = self.tools.tool {
            painter.text(
                render_rect.left_top() + egui::vec2(8.0, 8.0),
                egui::Align2::LEFT_TOP,
                format!("{} tool · Esc leaves", tool.name()),
                egui::FontId::proportional(13.0),
                egui::Color32::from_rgb(255, 140, 0),
            );
        }

        if !tool_used
            && response.clicked()
            && let Some(pos) = response.interact_pointer_pos()
            && state.settings.show_frusta
            && let Some(scene) = &state.scene
        {
            let cameras = state.survey_cameras();
            let click = Vec2::new(pos.x - render_rect.min.x, pos.y - render_rect.min.y);
            let depth = scene.frame.camera_distance * 0.08;
            if let Some(i) = overlay::pick_frustum(
                &overlay_camera,
                &cameras,
                depth,
                overlay::near_plane(&scene.frame),
                click,
                10.0,
            ) && state.snap.as_ref().is_none_or(|s| s.view != i)
            {
                commands.push(Command::SnapToView(i));
            }
        }

        if let Some(photo_rect) = photo_rect {
            self.draw_photo(ui, &painter, render_rect, photo_rect, state);
        }

        // Training snapshots repaint through the app's polling; only motion repaints at once.
        // A resting view asks for one more frame after the settle time to come back to full
        // resolution, not for a stream of frames (on a software driver each one costs the
        // trainer CPU time).
        if moving {
            ui.ctx().request_repaint();
        } else if self.resolution.settling() {
            ui.ctx()
                .request_repaint_after(std::time::Duration::from_millis(100));
        }
    }

    fn draw_overlays(
        &self,
        painter: &egui::Painter,
        rect: egui::Rect,
        camera: &Camera,
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
            let selected = state.snap.as_ref().map(|s| s.view);
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
                SegmentKind::Frustum => {
                    egui::Stroke::new(1.0, egui::Color32::from_rgb(80, 170, 255))
                }
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
        // The distance measurement: its points, the line between them and the distance.
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
}
