//! Selecting Gaussians by hand: screen shapes (rectangle, lasso or polygon, brush circle) tested
//! against each Gaussian's projected centre, world volumes (sphere, box), or damage (class above a
//! probability, survey first seen); the result combined with the current selection by a set
//! operation; and a person's damage class set or cleared on the selection. Every change is an
//! `Edit` that undoes itself when applied again (bits flipped, label values swapped), so undo and
//! redo keep no copy of the model (DESIGN.md: state as bits per Gaussian).

use glam::{Vec2, Vec3};

use super::Splats;
use super::model::state::{DELETED, HIDDEN, SELECTED};
use crate::scene::Camera;

/// How a shape's hits combine with the selection (SuperSplat's modifiers: none = set, Shift =
/// add, Ctrl = remove, Shift+Ctrl = intersect).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SetOp {
    Set,
    Add,
    Remove,
    Intersect,
}

impl SetOp {
    pub fn from_modifiers(shift: bool, ctrl: bool) -> SetOp {
        match (shift, ctrl) {
            (false, false) => SetOp::Set,
            (true, false) => SetOp::Add,
            (false, true) => SetOp::Remove,
            (true, true) => SetOp::Intersect,
        }
    }

    fn combine(self, selected: bool, hit: bool) -> bool {
        match self {
            SetOp::Set => hit,
            SetOp::Add => selected || hit,
            SetOp::Remove => selected && !hit,
            SetOp::Intersect => selected && hit,
        }
    }
}

/// What a selection tool drew: screen shapes in pixels of the camera's image, volumes in world
/// units.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// Axis-aligned rectangle between two corners.
    Rect {
        a: Vec2,
        b: Vec2,
    },
    /// Closed polygon (a lasso stroke or clicked points), even-odd rule.
    Polygon(Vec<Vec2>),
    /// Brush stroke: the union of circles of `radius` at `centres`.
    Brush {
        centres: Vec<Vec2>,
        radius: f32,
    },
    Sphere {
        centre: Vec3,
        radius: f32,
    },
    /// Axis-aligned box between two corners.
    Box {
        a: Vec3,
        b: Vec3,
    },
}

impl Shape {
    fn is_screen(&self) -> bool {
        matches!(
            self,
            Shape::Rect { .. } | Shape::Polygon(_) | Shape::Brush { .. }
        )
    }

    /// The screen box `(min, max)` a screen shape lies in (None for volumes and empty shapes).
    pub fn screen_bounds(&self) -> Option<(Vec2, Vec2)> {
        let bounds = |points: &[Vec2], pad: f32| {
            let first = *points.first()?;
            let (lo, hi) = points
                .iter()
                .fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p)));
            Some((lo - Vec2::splat(pad), hi + Vec2::splat(pad)))
        };
        match self {
            Shape::Rect { a, b } => Some((a.min(*b), a.max(*b))),
            Shape::Polygon(points) => bounds(points, 0.0),
            Shape::Brush { centres, radius } => bounds(centres, *radius),
            Shape::Sphere { .. } | Shape::Box { .. } => None,
        }
    }

    /// Whether screen point `p` (pixels) lies in the shape; volumes contain no pixel.
    pub fn contains_pixel(&self, p: Vec2) -> bool {
        match self {
            Shape::Rect { a, b } => {
                let (lo, hi) = (a.min(*b), a.max(*b));
                p.cmpge(lo).all() && p.cmple(hi).all()
            }
            Shape::Polygon(points) => inside_polygon(points, p),
            Shape::Brush { centres, radius } => centres
                .iter()
                .any(|c| c.distance_squared(p) <= radius * radius),
            Shape::Sphere { .. } | Shape::Box { .. } => false,
        }
    }

    fn contains_point(&self, p: Vec3) -> bool {
        match self {
            Shape::Sphere { centre, radius } => centre.distance_squared(p) <= radius * radius,
            Shape::Box { a, b } => {
                let (lo, hi) = (a.min(*b), a.max(*b));
                p.cmpge(lo).all() && p.cmple(hi).all()
            }
            _ => false,
        }
    }
}

/// Even-odd point-in-polygon test (fewer than three points contain nothing).
pub fn inside_polygon(points: &[Vec2], p: Vec2) -> bool {
    if points.len() < 3 {
        return false;
    }
    let mut inside = false;
    let mut j = points.len() - 1;
    for i in 0..points.len() {
        let (a, b) = (points[i], points[j]);
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// Per Gaussian: inside `shape`. Screen shapes test the centre's projection in front of
/// `camera` (straight through: hidden ones behind a wall count too); hidden and deleted
/// Gaussians are never hit.
pub fn hits(splats: &Splats, camera: &Camera, shape: &Shape) -> Vec<bool> {
    (0..splats.len())
        .map(|g| {
            if splats.meta.state[g] & (HIDDEN | DELETED) != 0 {
                return false;
            }
            let mean = splats.means[g];
            if shape.is_screen() {
                camera
                    .project(mean)
                    .is_some_and(|p| shape.contains_pixel(p))
            } else {
                shape.contains_point(mean)
            }
        })
        .collect()
}

/// A change to the model that undoes itself when applied again: state bits flipped, label
/// values or a whole model swapped with the ones it holds.
#[derive(Clone, Debug, PartialEq)]
pub enum Edit {
    /// Gaussians whose `bit` flipped.
    Bits { bit: u8, flipped: Vec<u32> },
    /// Gaussians whose raw labels were replaced; `labels` holds the other values
    /// (`label_channels` per Gaussian), swapped in and out by `apply`.
    Labels {
        gaussians: Vec<u32>,
        labels: Vec<f32>,
    },
    /// The whole model replaced (a refinement): the other model, swapped in and out.
    Model(Box<Splats>),
}

impl Edit {
    pub fn is_empty(&self) -> bool {
        match self {
            Edit::Bits { flipped, .. } => flipped.is_empty(),
            Edit::Labels { gaussians, .. } => gaussians.is_empty(),
            Edit::Model(_) => false,
        }
    }

    /// Applies the edit, or undoes it when it was applied last.
    pub fn apply(&mut self, splats: &mut Splats) {
        match self {
            Edit::Bits { bit, flipped } => {
                for &g in flipped.iter() {
                    splats.meta.state[g as usize] ^= *bit;
                }
            }
            Edit::Labels { gaussians, labels } => {
                let c = splats.label_channels;
                for (k, &g) in gaussians.iter().enumerate() {
                    let g = g as usize;
                    splats.raw_labels[g * c..(g + 1) * c]
                        .swap_with_slice(&mut labels[k * c..(k + 1) * c]);
                }
            }
            Edit::Model(other) => std::mem::swap(splats, other),
        }
    }
}

/// A label logit a person's "this is damage" sets (probability 0.9975), and its opposite.
pub const LABEL_ON: f32 = 6.0;
pub const LABEL_OFF: f32 = -6.0;

/// Sets (`on`) or clears damage class channel `channel` on the selected Gaussians: a person
/// overruling the segmenter. Nothing happens on a model without that channel.
pub fn set_label(splats: &mut Splats, channel: usize, on: bool) -> Edit {
    let c = splats.label_channels;
    let value = if on { LABEL_ON } else { LABEL_OFF };
    let gaussians: Vec<u32> = if channel < c {
        (0..splats.len())
            .filter(|&g| {
                splats.meta.state[g] & SELECTED != 0 && splats.raw_labels[g * c + channel] != value
            })
            .map(|g| g as u32)
            .collect()
    } else {
        Vec::new()
    };
    let mut labels = Vec::with_capacity(gaussians.len() * c);
    for &g in &gaussians {
        let mut row = splats.labels_of(g as usize).to_vec();
        row[channel] = value;
        labels.extend_from_slice(&row);
    }
    let mut edit = Edit::Labels { gaussians, labels };
    edit.apply(splats);
    edit
}

/// Per Gaussian: visible, with class channel `channel` at `threshold` or more (and, with
/// `survey`, first seen as damage in that survey).
pub fn damage_hits(
    splats: &Splats,
    channel: usize,
    threshold: f32,
    survey: Option<u16>,
) -> Vec<bool> {
    let c = splats.label_channels;
    (0..splats.len())
        .map(|g| {
            splats.meta.state[g] & (HIDDEN | DELETED) == 0
                && channel < c
                && super::model::sigmoid(splats.raw_labels[g * c + channel]) >= threshold
                && survey.is_none_or(|s| splats.meta.damage_survey[g] == s)
        })
        .collect()
}

/// The edit that sets `bit` to `want(g, current)` for every Gaussian, applied.
fn set_bit(splats: &mut Splats, bit: u8, want: impl Fn(usize, bool) -> bool) -> Edit {
    let flipped: Vec<u32> = (0..splats.len())
        .filter(|&g| {
            let current = splats.meta.state[g] & bit != 0;
            want(g, current) != current
        })
        .map(|g| g as u32)
        .collect();
    let mut edit = Edit::Bits { bit, flipped };
    edit.apply(splats);
    edit
}

/// Combines `hit` with the selection by `op`.
pub fn select(splats: &mut Splats, hit: &[bool], op: SetOp) -> Edit {
    set_bit(splats, SELECTED, |g, selected| op.combine(selected, hit[g]))
}

/// Selects every visible Gaussian (all = true) or none.
pub fn select_all(splats: &mut Splats, all: bool) -> Edit {
    let visible = visible(splats);
    set_bit(splats, SELECTED, |g, _| all && visible[g])
}

/// Selects the visible Gaussians that are not selected, and deselects the rest.
pub fn invert(splats: &mut Splats) -> Edit {
    let visible = visible(splats);
    set_bit(splats, SELECTED, |g, selected| visible[g] && !selected)
}

/// Hides the selection (hidden Gaussians are neither drawn nor hit). The selection bit stays.
pub fn hide_selected(splats: &mut Splats) -> Edit {
    let selected: Vec<bool> = splats
        .meta
        .state
        .iter()
        .map(|&s| s & SELECTED != 0)
        .collect();
    set_bit(splats, HIDDEN, |g, hidden| hidden || selected[g])
}

/// Shows every hidden Gaussian.
pub fn unhide_all(splats: &mut Splats) -> Edit {
    set_bit(splats, HIDDEN, |_, _| false)
}

fn visible(splats: &Splats) -> Vec<bool> {
    splats
        .meta
        .state
        .iter()
        .map(|&s| s & (HIDDEN | DELETED) == 0)
        .collect()
}

/// Selected Gaussians (visible ones only are ever selected by the tools).
pub fn selected_count(splats: &Splats) -> usize {
    splats
        .meta
        .state
        .iter()
        .filter(|&&s| s & SELECTED != 0)
        .count()
}

/// Undo and redo stacks of edits. A new edit clears the redo stack.
#[derive(Clone, Debug, Default)]
pub struct EditHistory {
    undo: Vec<Edit>,
    redo: Vec<Edit>,
}

/// Most edits kept for undo.
const HISTORY: usize = 200;

impl EditHistory {
    pub fn push(&mut self, edit: Edit) {
        if edit.is_empty() {
            return;
        }
        if self.undo.len() >= HISTORY {
            self.undo.remove(0);
        }
        self.undo.push(edit);
        self.redo.clear();
    }

    /// Undoes the last edit; false when there is none.
    pub fn undo(&mut self, splats: &mut Splats) -> bool {
        let Some(mut edit) = self.undo.pop() else {
            return false;
        };
        edit.apply(splats);
        self.redo.push(edit);
        true
    }

    pub fn redo(&mut self, splats: &mut Splats) -> bool {
        let Some(mut edit) = self.redo.pop() else {
            return false;
        };
        edit.apply(splats);
        self.undo.push(edit);
        true
    }

    /// Forgets every edit (the model they index was replaced).
    pub fn clear(&mut self) {
        self.undo.clear();
        self.redo.clear();
    }

    pub fn can_undo(&self) -> bool {
        !self.undo.is_empty()
    }

    pub fn can_redo(&self) -> bool {
        !self.redo.is_empty()
    }
}
