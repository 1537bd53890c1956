//! Damage known in 3D: per facade, cracks (polylines) and spalls (irregular patches, some with
//! exposed rebar) in facade (u, v) coordinates, for survey 1 and the grown survey 2. Evaluates
//! which class a surface point belongs to; must not shade or know about cameras.

use glam::{Vec2, Vec3};

use super::building::{BEAM_DEPTH, Building, COLUMN_HALF, Facade, SLAB_DEPTH};
use super::cracks::{Crack, CrackField, CrackSeed, extend_old_cracks, grow};
use super::geometry::{Component, Geometry, Prim, Ray};
use super::noise::{band_coverage, value_noise};
use crate::scene::DamageClass;

/// Bars exposed in the core of a spall.
#[derive(Clone, Debug, PartialEq)]
pub struct Rebar {
    /// Region id of the exposed bars (`truth/quantities.json`), their own beside the spall's.
    pub id: u32,
    /// Main bars run vertically (columns) or horizontally (beams).
    pub vertical: bool,
    /// Main bar centre lines across their direction (u for vertical bars, v for horizontal).
    pub bars: Vec<f32>,
    /// Tie spacing along the bars.
    pub tie_spacing: f32,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Spall {
    /// Region id (`truth/quantities.json`), kept when the spall grows.
    pub id: u32,
    pub facade: usize,
    pub centre: Vec2,
    pub radius: f32,
    pub seed: u32,
    pub rebar: Option<Rebar>,
}

/// Half the diameter of a main bar (28 mm bars); ties are 0.7 of it.
pub const BAR_HALF: f32 = 0.014;
/// Rebar shows where the spall is deeper than this fraction of its radius.
pub const REBAR_CORE: f32 = 0.72;
/// The largest boundary radius as a multiple of `Spall::radius` (0.7 + 0.45 + 0.2).
pub const BOUNDARY_MAX: f32 = 1.35;
/// Facade faces within this distance of the outer column plane carry the facade's damage.
const FACADE_DEPTH: f32 = 0.4;

impl Spall {
    /// The irregular boundary radius in direction `dir` (unit vector from the centre).
    pub fn boundary(&self, dir: Vec2) -> f32 {
        // Noise on a circle: the outline is periodic in angle and keeps its shape when grown.
        let n1 = value_noise(self.seed, 1.6 * dir.x + 20.0, 1.6 * dir.y + 20.0);
        let n2 = value_noise(self.seed ^ 0x55, 4.0 * dir.x + 40.0, 4.0 * dir.y + 40.0);
        self.radius * (0.7 + 0.45 * n1 + 0.2 * n2)
    }

    /// Whether facade point `p` lies inside the outline scaled by `fraction` (1: the spall,
    /// `REBAR_CORE`: its core). The same test as `DamageState::eval`'s, so what is measured
    /// against it partitions what `eval` classes.
    pub fn contains(&self, p: Vec2, fraction: f32) -> bool {
        let d = p - self.centre;
        let dist = d.length();
        if !(dist < BOUNDARY_MAX * fraction * self.radius) {
            return false;
        }
        let dir = if dist > 1e-6 { d / dist } else { Vec2::X };
        dist < fraction * self.boundary(dir)
    }
}

/// The damage at one surface point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DamageSample {
    /// The mask class of the point (classes are exclusive: rebar, then spalling, then crack).
    pub class: Option<DamageClass>,
    pub crack: f32,
    pub spall: f32,
    pub rebar: f32,
    /// 0 at a spall's rim, 1 at its centre (depth cue for shading).
    pub spall_depth: f32,
}

/// All damage of one survey.
#[derive(Clone, Debug)]
pub struct DamageState {
    pub cracks: [Vec<Crack>; 4],
    pub spalls: Vec<Spall>,
    fields: [CrackField; 4],
}

impl DamageState {
    pub(super) fn new(
        cracks: [Vec<Crack>; 4],
        spalls: Vec<Spall>,
        building: &Building,
    ) -> DamageState {
        let fields = std::array::from_fn(|f| {
            let fa = &building.facades[f];
            CrackField::new(&cracks[f], fa.u_range, (fa.v_range.0, fa.v_range.1 + 1.0))
        });
        DamageState {
            cracks,
            spalls,
            fields,
        }
    }

    /// Damage at facade point `p` for a pixel footprint `filter` (metres); `filter = 0` gives the
    /// exact classification.
    pub fn eval(&self, facade: usize, p: Vec2, filter: f32) -> DamageSample {
        let mut s = DamageSample::default();
        let mut in_spall = false;
        let mut in_rebar = false;
        for sp in self.spalls.iter().filter(|sp| sp.facade == facade) {
            let d = p - sp.centre;
            let dist = d.length();
            if dist > sp.radius * 1.4 + filter {
                continue;
            }
            let dir = if dist > 1e-6 { d / dist } else { Vec2::X };
            let r = sp.boundary(dir);
            let cov = ((r - dist) / filter.max(1e-5) + 0.5).clamp(0.0, 1.0);
            if cov > s.spall {
                s.spall = cov;
                s.spall_depth = (1.0 - dist / r).clamp(0.0, 1.0);
            }
            in_spall |= dist < r;
            if let Some(rebar) = &sp.rebar {
                let core = ((REBAR_CORE * r - dist) / filter.max(1e-5) + 0.5).clamp(0.0, 1.0);
                if core > 0.0 {
                    let (across, along) = if rebar.vertical {
                        (p.x, p.y)
                    } else {
                        (p.y, p.x)
                    };
                    let mut bar = 0.0f32;
                    let mut bar_dist = f32::INFINITY;
                    for &b in &rebar.bars {
                        bar_dist = bar_dist.min((across - b).abs());
                    }
                    bar = bar.max(band_coverage(bar_dist, BAR_HALF, filter));
                    let t = along / rebar.tie_spacing;
                    let tie_dist = (t - t.round()).abs() * rebar.tie_spacing;
                    let lo = rebar.bars.iter().cloned().fold(f32::INFINITY, f32::min);
                    let hi = rebar.bars.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
                    if across > lo - BAR_HALF && across < hi + BAR_HALF {
                        bar = bar.max(band_coverage(tie_dist, BAR_HALF * 0.7, filter));
                        bar_dist = bar_dist.min(tie_dist / 0.7);
                    }
                    s.rebar = s.rebar.max(bar * core);
                    in_rebar |= dist < REBAR_CORE * r && bar_dist < BAR_HALF.max(0.5 * filter);
                }
            }
        }
        let crack = self.fields[facade].query(p, filter);
        s.crack = crack.coverage * (1.0 - s.spall);
        s.class = if in_rebar {
            Some(DamageClass::Rebar)
        } else if in_spall {
            Some(DamageClass::Spalling)
        } else if crack.in_mask {
            Some(DamageClass::Crack)
        } else {
            None
        };
        s
    }
}

/// The facade whose damage a box face carries, with the point's facade coordinates.
pub fn damage_facade(
    building: &Building,
    prim: &Prim,
    face: u8,
    point: Vec3,
) -> Option<(usize, Vec2)> {
    if !matches!(
        prim.component,
        Component::Wall | Component::Column | Component::Beam
    ) {
        return None;
    }
    let axis = (face / 2) as usize;
    let positive = face % 2 == 1;
    let f = building
        .facades
        .iter()
        .position(|f| f.axis == axis && f.positive == positive)?;
    let fa = &building.facades[f];
    if !((point[axis] - fa.offset).abs() < FACADE_DEPTH) {
        return None;
    }
    Some((f, Vec2::new(point[1 - axis], point.z)))
}

/// The visible facade surface point at `(u, v)`, if the first surface seen from outside along
/// the facade normal carries the facade's damage.
pub fn surface_point(
    building: &Building,
    geometry: &Geometry,
    facade: usize,
    p: Vec2,
) -> Option<Vec3> {
    let fa: &Facade = &building.facades[facade];
    let n = fa.normal();
    let origin = fa.point(p.x, p.y, fa.offset) + n * 3.0;
    let ray = Ray::new(origin, -n);
    let hit = geometry.intersect(&ray, 10.0)?;
    let prim = geometry.prims.get(hit.prim as usize)?;
    let pos = ray.at(hit.t);
    let (f, _) = damage_facade(building, prim, hit.face, pos)?;
    (f == facade).then_some(pos)
}

/// The surface that carries facade `facade`'s damage at `(u, v)`, with its component: the first
/// face met along the inward normal from 5 cm outside the facade's outer plane (the column faces;
/// slab edges stand 2 cm proud of it), if it carries the facade's damage. Unlike `surface_point`
/// it starts inside things standing in front of the facade (balcony parapet, rubble): they hide
/// damage from some views, but the damage is on the structure all the same.
pub fn damage_surface(
    building: &Building,
    geometry: &Geometry,
    facade: usize,
    p: Vec2,
) -> Option<(Vec3, Component)> {
    let fa: &Facade = &building.facades[facade];
    let n = fa.normal();
    let ray = Ray::new(fa.point(p.x, p.y, fa.offset) + n * 0.05, -n);
    let hit = geometry.intersect(&ray, FACADE_DEPTH + 0.05)?;
    let prim = geometry.prims.get(hit.prim as usize)?;
    let pos = ray.at(hit.t);
    let (f, _) = damage_facade(building, prim, hit.face, pos)?;
    (f == facade).then_some((pos, prim.component))
}

/// How strongly each facade is damaged (front, right, back, left).
const SEVERITY: [f32; 4] = [1.0, 0.35, 0.3, 0.7];

/// Survey 1's damage and survey 2's (survey 1 plus new cracks and grown spalls).
pub fn generate(building: &Building, seed: u64) -> (DamageState, DamageState) {
    let mut rng = fastrand::Rng::with_seed(seed ^ 0xDA3A_6E00);
    // Region ids in order of creation; survey 2's new damage takes ids after all of survey 1's,
    // so an id names the same crack or spall in both surveys. Ids draw nothing from `rng`.
    let mut ids = RegionIds::default();
    let mut cracks: [Vec<Crack>; 4] = Default::default();
    let mut spalls = Vec::new();
    for f in 0..4 {
        add_cracks(building, f, SEVERITY[f], &mut rng, &mut ids, &mut cracks[f]);
        add_spalls(building, f, SEVERITY[f], &mut rng, &mut ids, &mut spalls);
    }
    let survey1 = DamageState::new(cracks.clone(), spalls.clone(), building);

    // Survey 2: spalls grow (their outline keeps its seed, so the old patch stays inside), old
    // cracks extend, and new cracks and spalls appear, mostly where damage already is.
    // The aftershock damage is concentrated on the front and left walls, so survey-2 views of
    // the back and right see no new damage.
    let active = |f: usize| SEVERITY[f] >= 0.5;
    for sp in &mut spalls {
        if active(sp.facade) && rng.f32() < 0.7 {
            sp.radius *= 1.25 + 0.25 * rng.f32();
            if sp.rebar.is_none() {
                sp.rebar = rebar_for(building, sp.facade, sp.centre, sp.radius, &mut ids);
            }
        }
    }
    for f in (0..4).filter(|&f| active(f)) {
        let bounds = facade_bounds(&building.facades[f]);
        let extended = extend_old_cracks(&mut rng, &cracks[f], |_| true, bounds, [0.4, 0.6], 0.012);
        cracks[f].extend(extended);
        let mut fresh = Vec::new();
        add_cracks(
            building,
            f,
            0.6 * SEVERITY[f],
            &mut rng,
            &mut ids,
            &mut fresh,
        );
        cracks[f].extend(fresh);
        if rng.f32() < SEVERITY[f] {
            add_spalls(building, f, 0.35, &mut rng, &mut ids, &mut spalls);
        }
    }
    let survey2 = DamageState::new(cracks, spalls, building);
    (survey1, survey2)
}

/// Hands out region ids in order.
#[derive(Default)]
pub(super) struct RegionIds {
    next: u32,
}

impl RegionIds {
    pub(super) fn take(&mut self) -> u32 {
        self.next += 1;
        self.next - 1
    }
}

pub(super) fn facade_bounds(f: &Facade) -> (Vec2, Vec2) {
    (
        Vec2::new(f.u_range.0, f.v_range.0 + 0.16),
        Vec2::new(f.u_range.1, f.v_range.1 + 0.8),
    )
}

pub(super) fn crack_width(rng: &mut fastrand::Rng) -> f32 {
    0.025 + 0.03 * rng.f32()
}

fn add_cracks(
    building: &Building,
    f: usize,
    severity: f32,
    rng: &mut fastrand::Rng,
    ids: &mut RegionIds,
    out: &mut Vec<Crack>,
) {
    let fa = &building.facades[f];
    let bounds = facade_bounds(fa);
    let storey = building.spec.storey;
    // Shear cracks from window corners, diagonal and away from the opening; lower floors more.
    for o in building.openings.iter().filter(|o| o.facade == f) {
        let floor_factor = if o.floor <= 2 { 1.0 } else { 0.4 };
        if !(rng.f32() < 0.8 * severity * floor_factor) {
            continue;
        }
        let corners = [
            (Vec2::new(o.u1, o.v1), 0.78f32),
            (Vec2::new(o.u0, o.v1), 2.36),
            (Vec2::new(o.u0, o.v0), 3.93),
            (Vec2::new(o.u1, o.v0), 5.50),
        ];
        let first = rng.usize(0..4);
        let count = 1 + rng.usize(0..2);
        for k in 0..count {
            let (corner, angle) = corners[(first + 2 * k) % 4];
            let dir = Vec2::new(angle.cos(), angle.sin());
            let cs = CrackSeed {
                start: corner + dir * 0.03,
                angle: angle + (rng.f32() - 0.5) * 0.4,
                length: 1.0 + 1.2 * rng.f32(),
                width: crack_width(rng),
                region: ids.take(),
            };
            grow(rng, cs, bounds, 0, out);
        }
    }
    // X-shaped cracks in piers and wall panels of the lower floors.
    let n_x = (5.0 * severity).round() as usize;
    for _ in 0..n_x {
        let u = fa.u_range.0 + 0.5 + rng.f32() * (fa.u_range.1 - fa.u_range.0 - 1.0);
        let floor = rng.usize(0..2.min(building.spec.floors as usize)) as f32;
        let v = floor * storey + 0.8 + rng.f32() * (storey - 1.6);
        let centre = Vec2::new(u, v);
        let width = crack_width(rng);
        // The four arms of an X are one region: they meet, and a mask shows one crack.
        let region = ids.take();
        for k in 0..4 {
            let angle = 0.78 + k as f32 * std::f32::consts::FRAC_PI_2 + (rng.f32() - 0.5) * 0.3;
            let cs = CrackSeed {
                start: centre,
                angle,
                length: 0.6 + 0.8 * rng.f32(),
                width,
                region,
            };
            grow(rng, cs, bounds, 0, out);
        }
    }
    // Flexural cracks across column ends and diagonal shear cracks in columns.
    for c in building.columns.iter().filter(|c| c.facade == f) {
        for floor in 0..building.spec.floors.min(2) {
            if !(rng.f32() < 0.5 * severity) {
                continue;
            }
            let base = floor as f32 * storey;
            let top = base + storey - BEAM_DEPTH;
            let v = if rng.bool() {
                base + 0.25 + 0.3 * rng.f32()
            } else {
                top - 0.15 - 0.3 * rng.f32()
            };
            let diagonal = rng.f32() < 0.35;
            let (start, angle, length) = if diagonal {
                (Vec2::new(c.u - COLUMN_HALF, v), 0.9f32, 0.75)
            } else {
                (Vec2::new(c.u - COLUMN_HALF - 0.05, v), 0.0, 0.5)
            };
            let angle = if rng.bool() && diagonal {
                std::f32::consts::PI - angle
            } else {
                angle
            };
            let start = if angle > 1.6 {
                start + Vec2::new(2.0 * COLUMN_HALF, 0.0)
            } else {
                start
            };
            let cs = CrackSeed {
                start,
                angle: angle + (rng.f32() - 0.5) * 0.15,
                length,
                width: 0.015 + 0.015 * rng.f32(),
                region: ids.take(),
            };
            grow(rng, cs, bounds, 1, out);
        }
    }
}

fn rebar_for(
    building: &Building,
    facade: usize,
    centre: Vec2,
    radius: f32,
    ids: &mut RegionIds,
) -> Option<Rebar> {
    if !(radius > 0.26) {
        return None;
    }
    let storey = building.spec.storey;
    let col = building
        .columns
        .iter()
        .filter(|c| c.facade == facade)
        .map(|c| c.u)
        .min_by(|a, b| (a - centre.x).abs().total_cmp(&(b - centre.x).abs()))?;
    let floor_top = ((centre.y / storey).floor() + 1.0) * storey;
    let in_beam = centre.y > floor_top - BEAM_DEPTH && (col - centre.x).abs() > COLUMN_HALF;
    if (col - centre.x).abs() < COLUMN_HALF + 0.1 {
        Some(Rebar {
            id: ids.take(),
            vertical: true,
            bars: vec![col - 0.13, col, col + 0.13],
            tie_spacing: 0.2,
        })
    } else if in_beam {
        let mid = floor_top - 0.5 * (BEAM_DEPTH + SLAB_DEPTH);
        Some(Rebar {
            id: ids.take(),
            vertical: false,
            bars: vec![mid - 0.14, mid + 0.14],
            tie_spacing: 0.2,
        })
    } else {
        None
    }
}

fn add_spalls(
    building: &Building,
    f: usize,
    severity: f32,
    rng: &mut fastrand::Rng,
    ids: &mut RegionIds,
    out: &mut Vec<Spall>,
) {
    let storey = building.spec.storey;
    let columns: Vec<f32> = building
        .columns
        .iter()
        .filter(|c| c.facade == f)
        .map(|c| c.u)
        .collect();
    for &u in &columns {
        // Column bases (soft storey) and beam-column joints.
        let r = rng.f32();
        let (centre, radius) = if r < 0.45 * severity {
            (
                Vec2::new(u + (rng.f32() - 0.5) * 0.15, 0.45 + 0.5 * rng.f32()),
                0.25 + 0.22 * rng.f32(),
            )
        } else if r < 0.75 * severity {
            let level = (1 + rng.u32(0..building.spec.floors.min(2))) as f32 * storey;
            (
                Vec2::new(u + (rng.f32() - 0.5) * 0.3, level - 0.45 - 0.3 * rng.f32()),
                0.25 + 0.18 * rng.f32(),
            )
        } else {
            continue;
        };
        let id = ids.take();
        out.push(Spall {
            id,
            facade: f,
            centre,
            radius,
            seed: rng.u32(..),
            rebar: rebar_for(building, f, centre, radius, ids),
        });
    }
    // Plaster or cover spalls on wall panels.
    let fa = &building.facades[f];
    let n = (2.0 * severity).round() as usize;
    for _ in 0..n {
        let centre = Vec2::new(
            fa.u_range.0 + 0.6 + rng.f32() * (fa.u_range.1 - fa.u_range.0 - 1.2),
            0.6 + rng.f32() * (storey * 2.0 - 1.2).min(fa.v_range.1 - 1.2),
        );
        out.push(Spall {
            id: ids.take(),
            facade: f,
            centre,
            radius: 0.2 + 0.25 * rng.f32(),
            seed: rng.u32(..),
            rebar: None,
        });
    }
}

/// A point on a visible damaged surface, for tests and checks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DamagePoint {
    pub class: DamageClass,
    pub position: Vec3,
}

/// Points of `state`'s damage on the surfaces, sampled every `spacing` metres over each facade,
/// classified exactly; with `previous`, only damage that is new since it.
pub fn damage_points(
    building: &Building,
    geometry: &Geometry,
    state: &DamageState,
    previous: Option<&DamageState>,
    spacing: f32,
) -> Vec<DamagePoint> {
    let mut out = Vec::new();
    for (f, fa) in building.facades.iter().enumerate() {
        let nu = ((fa.u_range.1 - fa.u_range.0) / spacing) as usize;
        let nv = ((fa.v_range.1 + 0.8 - fa.v_range.0) / spacing) as usize;
        for j in 0..nv {
            for i in 0..nu {
                let p = Vec2::new(
                    fa.u_range.0 + (i as f32 + 0.5) * spacing,
                    fa.v_range.0 + (j as f32 + 0.5) * spacing,
                );
                let Some(class) = state.eval(f, p, 0.0).class else {
                    continue;
                };
                if previous.is_some_and(|prev| prev.eval(f, p, 0.0).class == Some(class)) {
                    continue;
                }
                if let Some(position) = surface_point(building, geometry, f, p) {
                    out.push(DamagePoint { class, position });
                }
            }
        }
    }
    out
}
