//! The 3D viewport: turns mouse and keys into camera input (orbit / pan / zoom, fly with
//! WASD/QE), picks the render resolution, draws the splats through the GPU paint callback, then
//! the grid, the survey frusta (click one to snap to it) and the photo comparison on top.
//! It reads the state and changes it only through commands: what this frame drew with (the
//! camera's move, the viewport's size) goes back to the app at once, the rest waits in the queue.

mod navigation;
mod overlays;
mod photo;
mod pictures;

use std::sync::Arc;

use crate::app::commands::Command;
use crate::app::cpu_view::CpuView;
use crate::app::frame_log::FrameLog;
use crate::app::resolution::{AdaptiveResolution, FrameSample, scaled_size};
use crate::app::settings::ViewportRenderer;
use crate::app::settings::{CompareMode, SurveyLayout};
use crate::app::splat_view::{SLOTS, SplatView};
use crate::app::state::{AppState, Snap};
use crate::app::tools::ToolState;
use crate::scene::{Camera, RgbImage};
use crate::splats::Splats;
use crate::splats::selection::SetOp;
use navigation::{FrameView, navigate};
use overlays::{draw_overlays, snap_on_frustum_click};

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

/// What one frame draws where, and with which renderer, worked out before anything is drawn.
struct FramePlan {
    /// The whole viewport, in points.
    full: egui::Rect,
    /// Where the model is rendered.
    render_rect: egui::Rect,
    /// Where the snapped view's photo goes (None when not snapped).
    photo_rect: Option<egui::Rect>,
    /// The survey compared with the one shown, and its model.
    compared: Option<(usize, Arc<Splats>)>,
    /// The compared survey's picture goes beside the shown one (else under it, split by the
    /// swipe handle).
    side_by_side: bool,
    /// The CPU workers draw the splats this frame, not the GPU pass.
    use_cpu: bool,
}

/// Where the render and the snapped view's photo go in `full`: at the snapped camera's aspect
/// (the photo in the left half when side by side), else the whole viewport (its right half when
/// a compared survey's picture is beside it).
fn picture_rects(
    full: egui::Rect,
    snap: Option<&Snap>,
    compare: CompareMode,
    compared_beside: bool,
) -> (egui::Rect, Option<egui::Rect>) {
    let snap_aspect = snap.map(|s| {
        let k = s.camera.intrinsics;
        (k.width as f32, k.height as f32)
    });
    match snap_aspect {
        Some((w, h)) if compare == CompareMode::SideBySide => {
            let (left, right) = full.split_left_right_at_fraction(0.5);
            (fit_aspect(right, w, h), Some(fit_aspect(left, w, h)))
        }
        Some((w, h)) => {
            let r = fit_aspect(full, w, h);
            (r, Some(r))
        }
        None if compared_beside => (full.split_left_right_at_fraction(0.5).1, None),
        None => (full, None),
    }
}

/// The render rectangle's size in pixels, and the size rendered at `scale` of it.
fn render_sizes(
    render_rect: egui::Rect,
    pixels_per_point: f32,
    scale: f32,
) -> ([u32; 2], [u32; 2]) {
    let px_w = (render_rect.width() * pixels_per_point).round().max(1.0) as u32;
    let px_h = (render_rect.height() * pixels_per_point).round().max(1.0) as u32;
    let (rw, rh) = scaled_size(px_w, px_h, scale);
    ([px_w, px_h], [rw, rh])
}

/// The settings' background colour (0–1 channels) as egui paints it.
fn background_colour(bg: [f32; 3]) -> egui::Color32 {
    egui::Color32::from_rgb(
        (bg[0] * 255.0) as u8,
        (bg[1] * 255.0) as u8,
        (bg[2] * 255.0) as u8,
    )
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

    /// Draws this frame. The selection tools and a click on a survey frustum queue their commands
    /// in `commands`, applied before the next frame like a panel's. The returned commands are what
    /// this frame was drawn with (the camera's move, leaving a snapped view, the viewport's size
    /// and frame statistics): the app applies them at once, so the state is what the picture
    /// shows before anything else reads it, as when the viewport changed it directly.
    pub fn ui(
        &mut self,
        ui: &mut egui::Ui,
        state: &AppState,
        commands: &mut Vec<Command>,
    ) -> Vec<Command> {
        let full = ui.available_rect_before_wrap();
        let response = ui.allocate_rect(full, egui::Sense::click_and_drag());
        self.rect = Some(full);
        let painter = ui.painter_at(full);
        painter.rect_filled(full, 0.0, background_colour(state.settings.background));

        let mut drawn_with = Vec::new();
        let tool_chosen = self.tools.tool.is_some();
        let (view, input) = navigate(
            ui,
            &response,
            full.height(),
            tool_chosen,
            state,
            &mut drawn_with,
        );
        let plan = self.plan(full, &view, state);
        let moving = input.is_active() || view.camera.is_moving();
        let scale = self.render_scale(ui, state, &plan, moving);
        let render_rect = plan.render_rect;
        let (pixels, [rw, rh]) = render_sizes(render_rect, ui.ctx().pixels_per_point(), scale);
        let camera = view.camera_at(rw, rh);
        drawn_with.push(Command::RecordViewportFrame {
            pixels,
            stats: FrameStats {
                frame_ms: self.resolution.frame_ms(),
                render_scale: scale,
                render_size: [rw, rh],
            },
        });

        self.rendered_last_frame = self.draw_models(ui, &painter, &plan, &camera, &view, state);
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
        let overlay_camera = view.camera_at(
            render_rect.width().max(1.0) as u32,
            render_rect.height().max(1.0) as u32,
        );
        draw_overlays(&painter, &plan, &overlay_camera, &view, state);
        let tool_used = self.use_tools(
            ui,
            &painter,
            &response,
            render_rect,
            &overlay_camera,
            commands,
        );
        if !tool_used {
            snap_on_frustum_click(
                &response,
                render_rect,
                &overlay_camera,
                &view,
                state,
                commands,
            );
        }

        if let (Some(photo_rect), Some(snap)) = (plan.photo_rect, view.snap) {
            self.draw_photo(ui, &painter, render_rect, photo_rect, snap, state);
        }
        self.request_repaint(ui.ctx(), moving);
        drawn_with
    }

    /// Lays this frame out: the render and photo rectangles, the compared survey (not while
    /// looking through a survey camera) and the renderer.
    fn plan(&self, full: egui::Rect, view: &FrameView, state: &AppState) -> FramePlan {
        // A second survey beside the one shown (not while looking through a survey camera).
        let compared = state
            .timeline
            .as_ref()
            .filter(|_| view.snap.is_none())
            .and_then(|t| t.compared());
        let side_by_side = state.settings.survey_layout == SurveyLayout::SideBySide;
        let (render_rect, photo_rect) = picture_rects(
            full,
            view.snap,
            state.settings.compare_mode,
            compared.is_some() && side_by_side,
        );
        FramePlan {
            full,
            render_rect,
            photo_rect,
            compared,
            side_by_side,
            use_cpu: self.uses_cpu_renderer(state.settings.viewport_renderer),
        }
    }

    /// The render scale of this frame (1 unless the resolution adapts to the frame-time budget),
    /// from the time of the last render; records the frame in the frame log.
    fn render_scale(
        &mut self,
        ui: &egui::Ui,
        state: &AppState,
        plan: &FramePlan,
        moving: bool,
    ) -> f32 {
        let frame_ms = ui.input(|i| i.unstable_dt) * 1000.0;
        let pictures = if plan.compared.is_some() { 2 } else { 1 };
        let received = if plan.use_cpu {
            self.receive_cpu_pictures(ui.ctx(), pictures)
        } else {
            None
        };
        let (sample_ms, sample_rendered) = match received {
            Some(render_ms) => (render_ms, true),
            None if plan.use_cpu => (frame_ms, false),
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
        self.frame_log
            .record(ui.ctx(), frame_ms, scale, self.rendered_last_frame);
        if sample_rendered && plan.use_cpu {
            self.frame_log.record_render(sample_ms);
        }
        scale
    }

    /// Starts the CPU workers of the first `pictures` slots (once) and takes the pictures they
    /// finished. Returns the slowest of their render times: the pictures arrive between frames
    /// and carry their own render time, where the UI frames around them say nothing about what a
    /// render costs.
    fn receive_cpu_pictures(&mut self, ctx: &egui::Context, pictures: usize) -> Option<f32> {
        for view in self.cpu_views.iter_mut().take(pictures) {
            if view.is_none() {
                *view = Some(CpuView::start(ctx));
            }
        }
        self.cpu_views
            .iter_mut()
            .take(pictures)
            .filter_map(|v| match v {
                Some(Ok(view)) => view.receive(ctx),
                _ => None,
            })
            .reduce(f32::max)
    }

    /// Lets the selection tool read keys and the pointer (its commands go to `commands`), then
    /// draws its shape and names it. Returns true when the pointer was the tool's this frame.
    fn use_tools(
        &mut self,
        ui: &egui::Ui,
        painter: &egui::Painter,
        response: &egui::Response,
        render_rect: egui::Rect,
        camera: &Camera,
        commands: &mut Vec<Command>,
    ) -> bool {
        self.tools.keys(ui.ctx(), camera, commands);
        let op = ui.input(|i| SetOp::from_modifiers(i.modifiers.shift, i.modifiers.command));
        let tool_used = self
            .tools
            .pointer(response, render_rect.min, camera, op, commands);
        self.tools
            .draw(painter, render_rect.min, response.hover_pos());
        if let Some(tool) = self.tools.tool {
            painter.text(
                render_rect.left_top() + egui::vec2(8.0, 8.0),
                egui::Align2::LEFT_TOP,
                format!("{} tool · Esc leaves", tool.name()),
                egui::FontId::proportional(13.0),
                egui::Color32::from_rgb(255, 140, 0),
            );
        }
        tool_used
    }

    /// Training snapshots repaint through the app's polling; only motion repaints at once. A
    /// resting view asks for one more frame after the settle time to come back to full
    /// resolution, not for a stream of frames (on a software driver each one costs the trainer
    /// CPU time).
    fn request_repaint(&self, ctx: &egui::Context, moving: bool) {
        if moving {
            ctx.request_repaint();
        } else if self.resolution.settling() {
            ctx.request_repaint_after(std::time::Duration::from_millis(100));
        }
    }
}
