//! The demo structure: a reinforced-concrete frame (columns, beams, slabs) with brick or plaster
//! infill walls, framed windows with varied panes, a balcony, a roof parapet and a few props, all
//! as axis-aligned boxes. Only geometry and where openings are; textures and damage live elsewhere.

use glam::Vec3;

use super::geometry::{Component, Material, Prim};
use super::noise::{hash3, unit};

/// The building's size in bays and floors (all lengths in metres).
#[derive(Clone, Copy, Debug)]
pub struct BuildingSpec {
    pub floors: u32,
    pub bays_x: u32,
    pub bays_y: u32,
    pub bay_width: f32,
    pub bay_depth: f32,
    pub storey: f32,
    pub seed: u32,
}

/// One of the four outer walls. Facade coordinates are `u` = the world coordinate along the
/// facade (x for front/back, y for the sides) and `v` = height z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Facade {
    /// World axis of the outward normal (0 = x, 1 = y).
    pub axis: usize,
    /// Whether the outward normal points to +axis.
    pub positive: bool,
    /// Plane coordinate of the outer column faces.
    pub offset: f32,
    pub u_range: (f32, f32),
    pub v_range: (f32, f32),
    pub material: Material,
}

impl Facade {
    pub fn normal(&self) -> Vec3 {
        let mut n = Vec3::ZERO;
        n[self.axis] = if self.positive { 1.0 } else { -1.0 };
        n
    }

    /// The world point at facade coordinates `(u, v)` on the plane `offset`.
    pub fn point(&self, u: f32, v: f32, offset: f32) -> Vec3 {
        let mut p = Vec3::new(0.0, 0.0, v);
        p[self.axis] = offset;
        p[1 - self.axis] = u;
        p
    }
}

/// A window or door opening in facade coordinates.
#[derive(Clone, Copy, Debug)]
pub struct Opening {
    pub facade: usize,
    pub floor: u32,
    pub u0: f32,
    pub u1: f32,
    pub v0: f32,
    pub v1: f32,
}

/// A column seen on a facade: its centre line `u`.
#[derive(Clone, Copy, Debug)]
pub struct FacadeColumn {
    pub facade: usize,
    pub u: f32,
}

pub struct Building {
    pub spec: BuildingSpec,
    pub prims: Vec<Prim>,
    /// Front (-y), right (+x), back (+y), left (-x).
    pub facades: [Facade; 4],
    pub openings: Vec<Opening>,
    pub columns: Vec<FacadeColumn>,
    pub min: Vec3,
    pub max: Vec3,
}

pub const COLUMN_HALF: f32 = 0.2;
pub const BEAM_DEPTH: f32 = 0.6;
pub const SLAB_DEPTH: f32 = 0.2;
const BEAM_HALF: f32 = 0.17;
const WALL_HALF: f32 = 0.1;
const PLINTH: f32 = 0.15;

impl Building {
    pub fn new(spec: BuildingSpec) -> Building {
        let width = spec.bays_x as f32 * spec.bay_width;
        let depth = spec.bays_y as f32 * spec.bay_depth;
        let top = spec.floors as f32 * spec.storey;
        let o = COLUMN_HALF;
        let facade = |axis: usize, positive: bool, offset: f32, len: f32, material| Facade {
            axis,
            positive,
            offset,
            u_range: (-o, len + o),
            v_range: (0.0, top),
            material,
        };
        let facades = [
            facade(1, false, -o, width, Material::Brick),
            facade(0, true, width + o, depth, Material::Plaster),
            facade(1, true, depth + o, width, Material::Brick),
            facade(0, false, -o, depth, Material::Plaster),
        ];
        let mut b = Builder {
            spec,
            prims: Vec::new(),
            openings: Vec::new(),
            columns: Vec::new(),
            counter: 0,
        };
        b.frame(width, depth, top);
        for (f, facade) in facades.iter().enumerate() {
            b.facade(f, facade, width, depth);
        }
        if spec.floors >= 2 && spec.bays_x >= 3 {
            b.balcony();
        }
        b.roof(width, depth, top);
        b.props(width);
        let (min, max) = prims_bounds(&b.prims);
        Building {
            spec,
            prims: b.prims,
            facades,
            openings: b.openings,
            columns: b.columns,
            min,
            max,
        }
    }

    /// Centre of the building's bounding box.
    pub fn centre(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Grid line coordinates along a facade (column centres).
    pub fn grid(&self, facade: usize) -> Vec<f32> {
        let (n, step) = if self.facades[facade].axis == 1 {
            (self.spec.bays_x, self.spec.bay_width)
        } else {
            (self.spec.bays_y, self.spec.bay_depth)
        };
        (0..=n).map(|i| i as f32 * step).collect()
    }
}

struct Builder {
    spec: BuildingSpec,
    prims: Vec<Prim>,
    openings: Vec<Opening>,
    columns: Vec<FacadeColumn>,
    counter: u32,
}

impl Builder {
    fn push(&mut self, min: Vec3, max: Vec3, component: Component, material: Material) {
        self.counter += 1;
        let seed = hash3(self.spec.seed, self.counter, 17, 3);
        self.prims
            .push(Prim::new(min, max, component, material, seed));
    }

    fn rand(&mut self, salt: u32) -> f32 {
        self.counter += 1;
        unit(hash3(self.spec.seed, self.counter, salt, 11))
    }

    /// A box in facade coordinates: `u` along the facade, `d` outwards from the grid line, `z` up.
    #[allow(clippy::too_many_arguments)]
    fn facade_box(
        &mut self,
        f: &Facade,
        line: f32,
        u: (f32, f32),
        d: (f32, f32),
        z: (f32, f32),
        component: Component,
        material: Material,
    ) {
        if !(u.1 - u.0 > 1e-3 && z.1 - z.0 > 1e-3) {
            return;
        }
        let s = if f.positive { 1.0 } else { -1.0 };
        let mut min = Vec3::new(0.0, 0.0, z.0);
        let mut max = Vec3::new(0.0, 0.0, z.1);
        min[f.axis] = line + s * d.0;
        max[f.axis] = line + s * d.1;
        min[1 - f.axis] = u.0;
        max[1 - f.axis] = u.1;
        self.push(min, max, component, material);
    }

    fn frame(&mut self, width: f32, depth: f32, top: f32) {
        let s = self.spec;
        let o = COLUMN_HALF;
        for i in 0..=s.bays_x {
            for j in 0..=s.bays_y {
                if i != 0 && i != s.bays_x && j != 0 && j != s.bays_y {
                    continue;
                }
                let c = Vec3::new(i as f32 * s.bay_width, j as f32 * s.bay_depth, 0.0);
                self.push(
                    c + Vec3::new(-o, -o, 0.0),
                    c + Vec3::new(o, o, top),
                    Component::Column,
                    Material::Concrete,
                );
            }
        }
        // Plinth and floor slabs, 2 cm proud of the columns so slab edges read as lines.
        let p = 0.35;
        self.push(
            Vec3::new(-p, -p, 0.0),
            Vec3::new(width + p, depth + p, PLINTH),
            Component::Slab,
            Material::Concrete,
        );
        let e = o + 0.02;
        for k in 1..=s.floors {
            let z = k as f32 * s.storey;
            self.push(
                Vec3::new(-e, -e, z - SLAB_DEPTH),
                Vec3::new(width + e, depth + e, z),
                Component::Slab,
                Material::Concrete,
            );
        }
    }

    fn facade(&mut self, fi: usize, f: &Facade, width: f32, depth: f32) {
        let s = self.spec;
        let (n, step) = if f.axis == 1 {
            (s.bays_x, s.bay_width)
        } else {
            (s.bays_y, s.bay_depth)
        };
        let line = match (f.axis, f.positive) {
            (1, false) | (0, false) => 0.0,
            (1, true) => depth,
            _ => width,
        };
        let o = COLUMN_HALF;
        for i in 0..n {
            let u0 = i as f32 * step;
            let col = FacadeColumn { facade: fi, u: u0 };
            self.columns.push(col);
            let (ua, ub) = (u0 + o, u0 + step - o);
            for k in 1..=s.floors {
                let z_top = k as f32 * s.storey;
                let beam_bottom = z_top - BEAM_DEPTH;
                self.facade_box(
                    f,
                    line,
                    (ua, ub),
                    (-BEAM_HALF, BEAM_HALF),
                    (beam_bottom, z_top - SLAB_DEPTH),
                    Component::Beam,
                    Material::Concrete,
                );
                let z_base = if k == 1 { PLINTH } else { z_top - s.storey };
                let opening = self.choose_opening(fi, i, k, ua, ub, z_base, beam_bottom);
                self.wall_with_opening(f, fi, line, (ua, ub), (z_base, beam_bottom), opening, k);
            }
        }
        self.columns.push(FacadeColumn {
            facade: fi,
            u: n as f32 * step,
        });
    }

    /// Window or door geometry for one bay of one floor, `None` for a solid panel.
    #[allow(clippy::too_many_arguments)]
    fn choose_opening(
        &mut self,
        fi: usize,
        bay: u32,
        floor: u32,
        ua: f32,
        ub: f32,
        z_base: f32,
        z_top: f32,
    ) -> Option<(f32, f32, f32, f32)> {
        let s = self.spec;
        let mid = 0.5 * (ua + ub);
        let span = ub - ua;
        let r = self.rand(5);
        let side = fi % 2 == 1;
        if side && r < 0.3 {
            return None;
        }
        let under_balcony = fi == 0 && floor == 2 && is_balcony_bay(bay, s.bays_x);
        if (fi == 0 && floor == 1 && bay == s.bays_x / 2) || under_balcony {
            // Entrance or balcony door: full height opening.
            let w = if under_balcony { 1.6 } else { 1.4 };
            return Some((
                mid - 0.5 * w,
                mid + 0.5 * w,
                z_base,
                (z_base + 2.3).min(z_top - 0.2),
            ));
        }
        let widths = [1.2f32, 1.5, 1.8, 2.1];
        let w = widths[(self.rand(6) * 4.0) as usize % 4].min(span - 0.6);
        let sill = z_base + 0.85 + 0.1 * self.rand(7);
        let h = 1.3 + 0.2 * self.rand(8);
        let shift = (self.rand(9) - 0.5) * (span - w - 0.6).max(0.0) * 0.5;
        Some((
            mid - 0.5 * w + shift,
            mid + 0.5 * w + shift,
            sill,
            (sill + h).min(z_top - 0.15),
        ))
    }

    #[allow(clippy::too_many_arguments)]
    fn wall_with_opening(
        &mut self,
        f: &Facade,
        fi: usize,
        line: f32,
        (ua, ub): (f32, f32),
        (za, zb): (f32, f32),
        opening: Option<(f32, f32, f32, f32)>,
        floor: u32,
    ) {
        let d = (-WALL_HALF, WALL_HALF);
        let m = f.material;
        let Some((u0, u1, v0, v1)) = opening else {
            self.facade_box(f, line, (ua, ub), d, (za, zb), Component::Wall, m);
            return;
        };
        self.facade_box(f, line, (ua, u0), d, (za, zb), Component::Wall, m);
        self.facade_box(f, line, (u1, ub), d, (za, zb), Component::Wall, m);
        self.facade_box(f, line, (u0, u1), d, (za, v0), Component::Wall, m);
        self.facade_box(f, line, (u0, u1), d, (v1, zb), Component::Wall, m);
        self.openings.push(Opening {
            facade: fi,
            floor,
            u0,
            u1,
            v0,
            v1,
        });
        if v0 > za + 0.1 {
            // Projecting concrete sill.
            self.facade_box(
                f,
                line,
                (u0 - 0.06, u1 + 0.06),
                (0.0, WALL_HALF + 0.06),
                (v0 - 0.06, v0),
                Component::Wall,
                Material::Concrete,
            );
        }
        // Frame (jambs, head, sill rail, a mullion on wide windows) and the pane, recessed.
        let fw = 0.06;
        let fd = (-0.03, 0.04);
        let fr = Component::WindowFrame;
        let mat = Material::Frame;
        self.facade_box(f, line, (u0, u0 + fw), fd, (v0, v1), fr, mat);
        self.facade_box(f, line, (u1 - fw, u1), fd, (v0, v1), fr, mat);
        self.facade_box(f, line, (u0 + fw, u1 - fw), fd, (v1 - fw, v1), fr, mat);
        self.facade_box(f, line, (u0 + fw, u1 - fw), fd, (v0, v0 + fw), fr, mat);
        if u1 - u0 > 1.45 {
            let c = 0.5 * (u0 + u1);
            self.facade_box(
                f,
                line,
                (c - 0.025, c + 0.025),
                fd,
                (v0 + fw, v1 - fw),
                fr,
                mat,
            );
        }
        self.facade_box(
            f,
            line,
            (u0 + fw, u1 - fw),
            (-0.01, 0.01),
            (v0 + fw, v1 - fw),
            Component::WindowPane,
            Material::Glass,
        );
    }

    fn balcony(&mut self) {
        let s = self.spec;
        let (i0, i1) = balcony_bays(s.bays_x);
        let x0 = i0 as f32 * s.bay_width + 0.3;
        let x1 = (i1 + 1) as f32 * s.bay_width - 0.3;
        let z = s.storey;
        let (y0, y1) = (-1.5, -COLUMN_HALF);
        let b = Component::Balcony;
        let m = Material::Plaster;
        self.push(
            Vec3::new(x0, y0, z - 0.18),
            Vec3::new(x1, y1, z),
            b,
            Material::Concrete,
        );
        self.push(
            Vec3::new(x0, y0, z),
            Vec3::new(x1, y0 + 0.12, z + 1.0),
            b,
            m,
        );
        self.push(
            Vec3::new(x0, y0 + 0.12, z),
            Vec3::new(x0 + 0.12, y1, z + 1.0),
            b,
            m,
        );
        self.push(
            Vec3::new(x1 - 0.12, y0 + 0.12, z),
            Vec3::new(x1, y1, z + 1.0),
            b,
            m,
        );
        // A metal handrail on the parapet.
        self.push(
            Vec3::new(x0, y0 - 0.02, z + 1.0),
            Vec3::new(x1, y0 + 0.08, z + 1.06),
            b,
            Material::Metal,
        );
    }

    fn roof(&mut self, width: f32, depth: f32, top: f32) {
        let e = COLUMN_HALF + 0.02;
        let t = 0.15;
        let h = 0.8;
        let w = Component::Wall;
        let m = Material::Plaster;
        self.push(
            Vec3::new(-e, -e, top),
            Vec3::new(width + e, -e + t, top + h),
            w,
            m,
        );
        self.push(
            Vec3::new(-e, depth + e - t, top),
            Vec3::new(width + e, depth + e, top + h),
            w,
            m,
        );
        self.push(
            Vec3::new(-e, -e + t, top),
            Vec3::new(-e + t, depth + e - t, top + h),
            w,
            m,
        );
        self.push(
            Vec3::new(width + e - t, -e + t, top),
            Vec3::new(width + e, depth + e - t, top + h),
            w,
            m,
        );
        // Stair housing and a water tank.
        let sx = width * 0.62;
        let sy = depth * 0.3;
        self.push(
            Vec3::new(sx, sy, top),
            Vec3::new(sx + 3.0, sy + 2.6, top + 2.4),
            Component::Other,
            Material::Concrete,
        );
        self.push(
            Vec3::new(sx + 0.4, sy + 0.5, top + 2.4),
            Vec3::new(sx + 1.6, sy + 1.7, top + 3.3),
            Component::Other,
            Material::Metal,
        );
    }

    /// Rubble blocks and a low garden wall: texture and depth for SfM around the building.
    fn props(&mut self, width: f32) {
        for k in 0..6 {
            let x = 0.8 + self.rand(20 + k) * (width - 1.6);
            let y = -0.9 - self.rand(30 + k) * 1.4;
            let sx = 0.15 + 0.35 * self.rand(40 + k);
            let sy = 0.15 + 0.3 * self.rand(50 + k);
            let sz = 0.08 + 0.2 * self.rand(60 + k);
            self.push(
                Vec3::new(x, y, 0.0),
                Vec3::new(x + sx, y + sy, sz),
                Component::Other,
                Material::Concrete,
            );
        }
        self.push(
            Vec3::new(-6.0, -7.0, 0.0),
            Vec3::new(-5.6, 2.0, 0.7),
            Component::Other,
            Material::Brick,
        );
        self.push(
            Vec3::new(width + 4.0, -3.0, 0.0),
            Vec3::new(width + 6.2, 1.5, 1.5),
            Component::Other,
            Material::Metal,
        );
    }
}

/// The front bays carrying the balcony (centre one or two).
pub fn balcony_bays(bays_x: u32) -> (u32, u32) {
    if bays_x >= 4 {
        (bays_x / 2 - 1, bays_x / 2)
    } else {
        (bays_x / 2, bays_x / 2)
    }
}

fn is_balcony_bay(bay: u32, bays_x: u32) -> bool {
    let (a, b) = balcony_bays(bays_x);
    bays_x >= 3 && bay >= a && bay <= b
}

/// The box holding every primitive (the structure's bounds).
pub(super) fn prims_bounds(prims: &[Prim]) -> (Vec3, Vec3) {
    let mut min = Vec3::splat(f32::INFINITY);
    let mut max = Vec3::splat(f32::NEG_INFINITY);
    for p in prims {
        min = min.min(p.min);
        max = max.max(p.max);
    }
    (min, max)
}
