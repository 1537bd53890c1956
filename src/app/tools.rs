//! Selection tools in the viewport, with SuperSplat's keys: R rectangle, L lasso, P polygon
//! (click points; Backspace drops one, Enter closes), B brush (`[` and `]` resize it, drawn as a
//! circle), and click tools: C the Gaussian under the pointer, I the eyedropper (its colour),
//! O a sphere and X a box around the surface point clicked, M the distance between two clicked
//! surface points. Esc leaves the tool. While a tool is active the primary button draws instead
//! of orbiting; the shape becomes a `Command::Select` (or `SelectAt`) with the set operation of
//! the modifiers held (none set, Shift add, Ctrl remove, Shift+Ctrl intersect).

use glam::Vec2;

use crate::app::commands::{Command, PointSelect};
use crate::scene::Camera;
use crate::splats::selection::{SetOp, Shape};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tool {
    Rect,
    Lasso,
    Polygon,
    Brush,
    /// A click tool: what a click selects.
    Click(PointSelect),
    /// Distance between two clicked surface points.
    Measure,
}

impl Tool {
    pub fn name(self) -> &'static str {
        match self {
            Tool::Rect => "rectangle",
            Tool::Lasso => "lasso",
            Tool::Polygon => "polygon",
            Tool::Brush => "brush",
            Tool::Click(PointSelect::Gaussian) => "click",
            Tool::Click(PointSelect::Colour) => "eyedropper",
            Tool::Click(PointSelect::Sphere) => "sphere",
            Tool::Click(PointSelect::Box) => "box",
            Tool::Measure => "measure",
        }
    }
}

/// Brush radius limits and default, in points.
const BRUSH_MIN: f32 = 2.0;
const BRUSH_MAX: f32 = 400.0;
const BRUSH_DEFAULT: f32 = 24.0;

/// The active tool and the shape being drawn (points relative to the render rectangle).
#[derive(Clone, Debug)]
pub struct ToolState {
    pub tool: Option<Tool>,
    pub points: Vec<Vec2>,
    pub brush_radius: f32,
}

impl Default for ToolState {
    fn default() -> Self {
        ToolState {
            tool: None,
            points: Vec::new(),
            brush_radius: BRUSH_DEFAULT,
        }
    }
}

impl ToolState {
    /// Tool keys (only when no text field has the keyboard).
    pub fn keys(&mut self, ctx: &egui::Context, camera: &Camera, commands: &mut Vec<Command>) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let pressed = |key| ctx.input_mut(|i| i.consume_key(egui::Modifiers::NONE, key));
        for (key, tool) in [
            (egui::Key::R, Tool::Rect),
            (egui::Key::L, Tool::Lasso),
            (egui::Key::P, Tool::Polygon),
            (egui::Key::B, Tool::Brush),
            (egui::Key::C, Tool::Click(PointSelect::Gaussian)),
            (egui::Key::I, Tool::Click(PointSelect::Colour)),
            (egui::Key::O, Tool::Click(PointSelect::Sphere)),
            (egui::Key::X, Tool::Click(PointSelect::Box)),
            (egui::Key::M, Tool::Measure),
        ] {
            if pressed(key) {
                self.tool = Some(tool);
                self.points.clear();
            }
        }
        if pressed(egui::Key::Escape) {
            self.tool = None;
            self.points.clear();
        }
        if self.tool == Some(Tool::Brush) {
            if pressed(egui::Key::OpenBracket) {
                self.brush_radius = (self.brush_radius / 1.25).max(BRUSH_MIN);
            }
            if pressed(egui::Key::CloseBracket) {
                self.brush_radius = (self.brush_radius * 1.25).min(BRUSH_MAX);
            }
        }
        if self.tool == Some(Tool::Polygon) {
            if pressed(egui::Key::Backspace) {
                self.points.pop();
            }
            let op = ctx.input(|i| SetOp::from_modifiers(i.modifiers.shift, i.modifiers.command));
            let enter = ctx.input_mut(|i| {
                i.consume_key(egui::Modifiers::NONE, egui::Key::Enter)
                    || i.consume_key(egui::Modifiers::SHIFT, egui::Key::Enter)
                    || i.consume_key(egui::Modifiers::COMMAND, egui::Key::Enter)
                    || i.consume_key(
                        egui::Modifiers::SHIFT | egui::Modifiers::COMMAND,
                        egui::Key::Enter,
                    )
            });
            if enter && self.points.len() >= 3 {
                let shape = Shape::Polygon(std::mem::take(&mut self.points));
                commands.push(select(shape, *camera, op));
            }
        }
    }

    /// Pointer input on the render rectangle: true when the tool used the primary button (the
    /// camera must not orbit with it).
    pub fn pointer(
        &mut self,
        response: &egui::Response,
        origin: egui::Pos2,
        camera: &Camera,
        op: SetOp,
        commands: &mut Vec<Command>,
    ) -> bool {
        let Some(tool) = self.tool else {
            return false;
        };
        let at = |p: egui::Pos2| Vec2::new(p.x - origin.x, p.y - origin.y);
        let primary = egui::PointerButton::Primary;
        match tool {
            Tool::Polygon => {
                if response.clicked_by(primary)
                    && let Some(p) = response.interact_pointer_pos()
                {
                    self.points.push(at(p));
                }
            }
            Tool::Click(how) => {
                if response.clicked_by(primary)
                    && let Some(p) = response.interact_pointer_pos()
                {
                    commands.push(Command::SelectAt {
                        pixel: at(p),
                        camera: Box::new(*camera),
                        how,
                        op,
                    });
                }
            }
            Tool::Measure => {
                if response.clicked_by(primary)
                    && let Some(p) = response.interact_pointer_pos()
                {
                    commands.push(Command::MeasureAt {
                        pixel: at(p),
                        camera: Box::new(*camera),
                    });
                }
            }
            Tool::Rect | Tool::Lasso | Tool::Brush => {
                if response.drag_started_by(primary) || response.clicked_by(primary) {
                    self.points.clear();
                    // The stroke starts where the button went down, not where egui saw a drag.
                    if let Some(origin) = response.ctx.input(|i| i.pointer.press_origin()) {
                        self.points.push(at(origin));
                    }
                }
                if (response.dragged_by(primary) || response.clicked_by(primary))
                    && let Some(p) = response.interact_pointer_pos()
                {
                    let p = at(p);
                    match tool {
                        Tool::Rect => {
                            self.points.truncate(1);
                            self.points.push(p);
                        }
                        _ if self.points.last() != Some(&p) => self.points.push(p),
                        _ => {}
                    }
                }
                if response.drag_stopped_by(primary) || response.clicked_by(primary) {
                    let points = std::mem::take(&mut self.points);
                    let shape = match tool {
                        Tool::Rect => points
                            .first()
                            .zip(points.last())
                            .map(|(&a, &b)| Shape::Rect { a, b }),
                        Tool::Lasso => (points.len() >= 3).then_some(Shape::Polygon(points)),
                        _ => (!points.is_empty()).then_some(Shape::Brush {
                            centres: points,
                            radius: self.brush_radius,
                        }),
                    };
                    if let Some(shape) = shape {
                        commands.push(select(shape, *camera, op));
                    }
                }
            }
        }
        true
    }

    /// Draws the shape in progress (and the brush under the pointer).
    pub fn draw(&self, painter: &egui::Painter, origin: egui::Pos2, hover: Option<egui::Pos2>) {
        let Some(tool) = self.tool else { return };
        let stroke = egui::Stroke::new(1.5, egui::Color32::from_rgb(255, 140, 0));
        let pos = |p: &Vec2| origin + egui::vec2(p.x, p.y);
        match tool {
            Tool::Rect => {
                if let (Some(a), Some(b)) = (self.points.first(), self.points.last()) {
                    let rect = egui::Rect::from_two_pos(pos(a), pos(b));
                    painter.rect_stroke(rect, 0.0, stroke, egui::StrokeKind::Middle);
                }
            }
            Tool::Lasso | Tool::Polygon => {
                let mut line: Vec<egui::Pos2> = self.points.iter().map(pos).collect();
                if tool == Tool::Polygon
                    && let Some(h) = hover
                {
                    line.push(h);
                }
                if line.len() >= 2 {
                    painter.add(egui::Shape::closed_line(line, stroke));
                }
            }
            Tool::Brush => {
                for p in &self.points {
                    painter.circle_stroke(pos(p), self.brush_radius, stroke);
                }
                if let Some(h) = hover {
                    painter.circle_stroke(h, self.brush_radius, stroke);
                }
            }
            Tool::Click(_) | Tool::Measure => {
                if let Some(h) = hover {
                    painter
                        .line_segment([h - egui::vec2(6.0, 0.0), h + egui::vec2(6.0, 0.0)], stroke);
                    painter
                        .line_segment([h - egui::vec2(0.0, 6.0), h + egui::vec2(0.0, 6.0)], stroke);
                }
            }
        }
    }
}

fn select(shape: Shape, camera: Camera, op: SetOp) -> Command {
    Command::Select {
        shape,
        camera: Box::new(camera),
        op,
    }
}
