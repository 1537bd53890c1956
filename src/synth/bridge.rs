//! The demo bridge: a multi-span concrete girder bridge (deck slab, four girders per span, pier
//! caps on pairs of pier columns with footings, abutments, parapets with a handrail) as
//! axis-aligned boxes, described as a `Building` so the ray caster, textures, ambient occlusion,
//! damage decals and truth writers of the building serve it unchanged. x runs along the bridge
//! (span `k` from `k * SPAN` to `(k + 1) * SPAN`), y across it (centre line y = 0), z up.
//! Only geometry; damage is `bridge_damage`, the drone strips `drone::bridge_path`.

use glam::Vec3;
use serde::Serialize;

use super::building::{Building, BuildingSpec, Facade, FacadeColumn, prims_bounds};
use super::geometry::{Component, Material, Prim};
use super::noise::hash3;

/// Span length (pier to pier), metres.
pub const SPAN: f32 = 20.0;
/// Deck width, parapet to parapet.
pub const DECK_WIDTH: f32 = 9.0;
/// Height of the deck slab's underside above the ground.
pub const CLEARANCE: f32 = 7.0;
pub const DECK_DEPTH: f32 = 0.3;
pub const GIRDER_DEPTH: f32 = 1.3;
pub const GIRDER_WIDTH: f32 = 0.5;
pub const GIRDERS: u32 = 4;
/// How far the deck slab overhangs the outer girders' outer faces.
pub const OVERHANG: f32 = 0.5;
pub const CAP_DEPTH: f32 = 1.1;
pub const CAP_HALF_LENGTH: f32 = 0.8;
/// Pier columns: square, their outer faces flush with the outer girders'.
pub const PIER_SIZE: f32 = 1.2;
const ABUTMENT_LENGTH: f32 = 4.0;
const PARAPET_HEIGHT: f32 = 0.8;
const PARAPET_WIDTH: f32 = 0.35;

/// The outer girders' outer faces (and the pier columns' and caps'): the side facades' plane is
/// y = -SIDE_PLANE (front) and y = +SIDE_PLANE (back).
pub const SIDE_PLANE: f32 = 0.5 * DECK_WIDTH - OVERHANG;

/// The bridge's length, abutments excluded.
pub fn length(spans: u32) -> f32 {
    spans as f32 * SPAN
}

/// The x of pier `i` (1..spans; 0 and spans are the abutments' faces).
pub fn support_x(i: u32) -> f32 {
    i as f32 * SPAN
}

/// Girder underside: where the girders' damage starts.
pub fn girder_bottom() -> f32 {
    CLEARANCE - GIRDER_DEPTH
}

/// The span containing `x` (clamped to the bridge).
pub fn span_of(x: f32, spans: u32) -> u32 {
    ((x / SPAN).floor().max(0.0) as u32).min(spans.saturating_sub(1))
}

/// The manifest's `world` line for a bridge.
pub const WORLD: &str = "z up, metres; ground plane z = 0; bridge along x: span k from 20 k to \
    20 (k + 1), piers at the span ends, abutments beyond 0 and the last span; deck centre line \
    y = 0, deck 9 m wide, its underside at z = 7; truth/bridge.json lists the spans; cameras in \
    COLMAP convention (world-to-camera, x right, y down, z forward)";

/// `truth/bridge.json`: where the spans are and which ones survey 2 changed, so a partition or a
/// timeline test can check itself against the truth.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BridgeLayout {
    pub spans: u32,
    pub span_length_m: f32,
    pub deck_width_m: f32,
    /// `[x0, x1]` of each span, in order.
    pub span_x_m: Vec<[f32; 2]>,
    /// The x of each pier (between spans).
    pub pier_x_m: Vec<f32>,
    /// Spans where survey 2's damage differs from survey 1's (grown or new); the others are
    /// identical in both surveys.
    pub changed_spans: Vec<u32>,
}

impl BridgeLayout {
    pub fn new(spans: u32, changed_spans: &[u32]) -> BridgeLayout {
        BridgeLayout {
            spans,
            span_length_m: SPAN,
            deck_width_m: DECK_WIDTH,
            span_x_m: (0..spans)
                .map(|k| [support_x(k), support_x(k + 1)])
                .collect(),
            pier_x_m: (1..spans).map(support_x).collect(),
            changed_spans: changed_spans.to_vec(),
        }
    }
}

/// The bridge as a structure of boxes. Its `spec` is the bridge read as a one-storey frame:
/// `bays_x` spans of `bay_width` = `SPAN`, one bay `DECK_WIDTH` deep, a storey up to the deck top
/// (textures use the storey to vary by floor; here everything is floor 0).
pub fn bridge(spans: u32, seed: u32) -> Building {
    let spans = spans.max(1);
    let len = length(spans);
    let top = CLEARANCE + DECK_DEPTH;
    let spec = BuildingSpec {
        floors: 1,
        bays_x: spans,
        bays_y: 1,
        bay_width: SPAN,
        bay_depth: DECK_WIDTH,
        storey: top,
        seed,
    };
    let side = |positive: bool| Facade {
        axis: 1,
        positive,
        offset: if positive { SIDE_PLANE } else { -SIDE_PLANE },
        u_range: (0.0, len),
        v_range: (0.0, CLEARANCE),
        material: Material::Concrete,
    };
    let end = |positive: bool| Facade {
        axis: 0,
        positive,
        offset: if positive {
            len + ABUTMENT_LENGTH
        } else {
            -ABUTMENT_LENGTH
        },
        u_range: (-0.5 * DECK_WIDTH, 0.5 * DECK_WIDTH),
        v_range: (0.0, top),
        material: Material::Concrete,
    };
    // Same order as the building's: front (-y), right (+x), back (+y), left (-x).
    let facades = [side(false), end(true), side(true), end(false)];
    let mut b = Boxes {
        seed,
        prims: Vec::new(),
    };
    let half = 0.5 * DECK_WIDTH;
    let concrete = Material::Concrete;
    for k in 0..spans {
        let (x0, x1) = (support_x(k), support_x(k + 1));
        b.push(
            Vec3::new(x0, -half, CLEARANCE),
            Vec3::new(x1, half, top),
            Component::Slab,
            concrete,
        );
        for g in 0..GIRDERS {
            let y0 =
                -SIDE_PLANE + g as f32 * (2.0 * SIDE_PLANE - GIRDER_WIDTH) / (GIRDERS - 1) as f32;
            b.push(
                Vec3::new(x0, y0, girder_bottom()),
                Vec3::new(x1, y0 + GIRDER_WIDTH, CLEARANCE),
                Component::Beam,
                concrete,
            );
        }
        for s in [-1.0f32, 1.0] {
            let (ya, yb) = (s * half, s * (half - PARAPET_WIDTH));
            b.push(
                Vec3::new(x0, ya, top),
                Vec3::new(x1, yb, top + PARAPET_HEIGHT),
                Component::Other,
                concrete,
            );
            let rail = s * (half - 0.5 * PARAPET_WIDTH);
            b.push(
                Vec3::new(x0, rail - 0.04, top + PARAPET_HEIGHT + 0.25),
                Vec3::new(x1, rail + 0.04, top + PARAPET_HEIGHT + 0.31),
                Component::Other,
                Material::Metal,
            );
        }
    }
    for i in 1..spans {
        let x = support_x(i);
        let cap_bottom = girder_bottom() - CAP_DEPTH;
        b.push(
            Vec3::new(x - CAP_HALF_LENGTH, -SIDE_PLANE, cap_bottom),
            Vec3::new(x + CAP_HALF_LENGTH, SIDE_PLANE, girder_bottom()),
            Component::Beam,
            concrete,
        );
        for s in [-1.0f32, 1.0] {
            let (ya, yb) = (s * SIDE_PLANE, s * (SIDE_PLANE - PIER_SIZE));
            b.push(
                Vec3::new(x - 0.5 * PIER_SIZE, ya, 0.0),
                Vec3::new(x + 0.5 * PIER_SIZE, yb, cap_bottom),
                Component::Column,
                concrete,
            );
            // Footings stand proud of the facade plane by more than the depth that carries
            // damage, so they stay clean.
            let (fa, fb) = (s * (SIDE_PLANE + 0.6), s * (SIDE_PLANE - PIER_SIZE - 0.6));
            b.push(
                Vec3::new(x - 1.4, fa, 0.0),
                Vec3::new(x + 1.4, fb, 0.35),
                Component::Other,
                concrete,
            );
        }
    }
    // Abutments: solid blocks up to the deck top, with wing walls' worth of width.
    for (xa, xb) in [(-ABUTMENT_LENGTH, 0.0), (len, len + ABUTMENT_LENGTH)] {
        b.push(
            Vec3::new(xa, -half - 0.3, 0.0),
            Vec3::new(xb, half + 0.3, top),
            Component::Wall,
            concrete,
        );
    }
    let columns = (0..=spans)
        .flat_map(|i| {
            [0, 2].map(|facade| FacadeColumn {
                facade,
                u: support_x(i),
            })
        })
        .collect();
    let (min, max) = prims_bounds(&b.prims);
    Building {
        spec,
        prims: b.prims,
        facades,
        openings: Vec::new(),
        columns,
        min,
        max,
    }
}

struct Boxes {
    seed: u32,
    prims: Vec<Prim>,
}

impl Boxes {
    fn push(&mut self, min: Vec3, max: Vec3, component: Component, material: Material) {
        let seed = hash3(self.seed, self.prims.len() as u32 + 1, 17, 5);
        self.prims
            .push(Prim::new(min, max, component, material, seed));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn side_facades_are_flush_with_girders_pier_columns_and_caps() {
        let b = bridge(3, 1);
        let on_front = |p: &Prim| (p.min.y + SIDE_PLANE).abs() < 1e-4;
        let front: Vec<Component> = b
            .prims
            .iter()
            .filter(|p| on_front(p))
            .map(|p| p.component)
            .collect();
        // 3 outer girders, 2 pier caps, 2 pier columns.
        assert_eq!(front.iter().filter(|&&c| c == Component::Beam).count(), 5);
        assert_eq!(front.iter().filter(|&&c| c == Component::Column).count(), 2);
        assert!((b.max.x - b.min.x - (60.0 + 2.0 * ABUTMENT_LENGTH)).abs() < 1e-4);
        assert_eq!(span_of(39.9, 3), 1);
        assert_eq!(span_of(75.0, 3), 2);
    }
}
