//! The viewport's navigation: mouse and keys become a `CameraInput` (orbit / pan / zoom, fly with
//! WASD/QE), which moves a copy of the state's camera that this frame draws with, while the
//! commands that make the state follow (`Unsnap`, `MoveCamera`) go back to the app.

use glam::{Vec2, Vec3};

use crate::app::camera_controller::{CameraController, CameraInput};
use crate::app::commands::Command;
use crate::app::state::{AppState, Snap, view_camera};
use crate::scene::Camera;

/// The view a frame is drawn from: the free camera after this frame's navigation, and the
/// survey view it stays snapped to (None once navigating has left it).
pub(super) struct FrameView<'a> {
    pub camera: CameraController,
    pub snap: Option<&'a Snap>,
}

impl FrameView<'_> {
    /// The camera to render with at `width × height` pixels (`AppState::view_camera` of the
    /// state once this frame's navigation has been applied).
    pub fn camera_at(&self, width: u32, height: u32) -> Camera {
        view_camera(self.snap, &self.camera, width, height)
    }
}

/// Reads this frame's navigation and moves a copy of the state's camera with it. Returns the
/// view to draw from and the input that moved it (none while snapped); pushes onto `drawn_with`
/// the commands that do the same to the state. While a selection tool is chosen, the primary
/// button draws the selection instead of rotating or panning.
pub(super) fn navigate<'a>(
    ui: &egui::Ui,
    response: &egui::Response,
    viewport_height: f32,
    tool_chosen: bool,
    state: &'a AppState,
    drawn_with: &mut Vec<Command>,
) -> (FrameView<'a>, CameraInput) {
    let mut input = camera_input(ui, response, viewport_height);
    if tool_chosen && response.dragged_by(egui::PointerButton::Primary) {
        // The primary button draws the selection (Shift and Ctrl pick its set operation).
        input.rotate = Vec2::ZERO;
        input.pan = Vec2::ZERO;
    }
    if state.settings.turntable && state.snap.is_none() && input.rotate == Vec2::ZERO {
        // 0.35 rad/s about the up axis, expressed as the drag that would do it.
        input.rotate.x = -0.35 * input.dt / state.camera.rotate_speed;
    }
    let mut view = FrameView {
        camera: state.camera.clone(),
        snap: state.snap.as_ref(),
    };
    if let Some(snap) = view.snap
        && input.is_active()
    {
        // Navigating leaves the survey camera, continuing from its pose.
        view.camera.snap_to(&snap.camera);
        view.snap = None;
        drawn_with.push(Command::Unsnap);
    }
    if view.snap.is_none() {
        view.camera.update(&input);
        drawn_with.push(Command::MoveCamera(input));
    } else {
        input = CameraInput::default();
    }
    (view, input)
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
