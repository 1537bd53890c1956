//! The true damage quantities of one survey (`truth/quantities.json`): crack centre-line lengths
//! and mean widths, spall areas and exposed rebar lengths, per region with ids stable across the
//! surveys, measured on the surfaces that carry damage and classed as the masks are. No rendering.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use glam::{DVec3, Vec2, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::area::{AREA_CELL, cells, polar_area};
use super::building::Building;
use super::cracks::Crack;
use super::damage::{
    BAR_HALF, BOUNDARY_MAX, DamageState, REBAR_CORE, Rebar, Spall, damage_surface,
};
use super::geometry::{Component, Geometry};
use super::params::SynthError;
use crate::scene::DamageClass;

/// Centre lines (cracks, bars) are measured at the midpoints of 5 mm steps: a crack is grown in
/// 35 mm steps, so each step is split in seven and a crack leaving a surface is cut within 5 mm.
pub const LINE_STEP: f32 = 0.005;
/// The whole file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quantities {
    pub survey: u32,
    /// The frame of `centroid`s: always the world (= twin, survey 1) frame.
    pub frame: String,
    pub spalling_area_includes_rebar: bool,
    pub totals: Totals,
    pub regions: Vec<Region>,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Totals {
    /// Crack centre lines on damage-carrying surfaces and classed crack (not inside a spall).
    pub crack_length_m: f32,
    /// Surface classed spalling (exposed rebar excluded, as in the masks).
    pub spalling_area_m2: f32,
    /// Exposed bar centre lines (main bars and ties).
    pub rebar_length_m: f32,
    /// Surface classed rebar.
    pub rebar_area_m2: f32,
    /// The generated crack polylines in full, wherever they lie (over windows, slabs, spalls).
    pub crack_polyline_length_m: f32,
    /// The spall outlines' areas in full (`Spall::boundary`), overlaps counted twice.
    pub spall_outline_area_m2: f32,
    pub cracks: usize,
    pub spalls: usize,
    pub rebar: usize,
    /// Regions absent in survey 1.
    pub new_regions: usize,
}

/// One crack (a main crack with its branches and extensions), spall, or spall's exposed bars.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Region {
    pub id: u32,
    /// `crack`, `spalling` or `rebar`.
    pub class: String,
    /// 0 front (-y), 1 right (+x), 2 back (+y), 3 left (-x).
    pub facade: usize,
    /// The component (`truth/components` name and id) carrying most of the region.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub component: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub component_id: Option<u8>,
    /// Mean surface point (metres, world frame), weighted by length or area; the outline's
    /// centre on the facade plane when none of the region is on a damage-carrying surface.
    pub centroid: [f32; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length_m: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub polyline_length_m: Option<f32>,
    /// Crack: mean width over `length_m`; rebar: mean bar diameter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width_m: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub area_m2: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outline_area_m2: Option<f32>,
    /// Rebar: the id of the spall it shows in.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spall: Option<u32>,
    pub first_survey: u32,
    pub new: bool,
}

/// The schema in words, for the manifest and docs/SYNTH.md.
pub const SCHEMA: &str = "truth/quantities.json: the true damage of this survey's state of the \
    building. `totals`: crack_length_m (crack centre lines, branches included, on the faces that \
    carry damage and not inside a spall: what the masks can show), spalling_area_m2 (surface \
    classed spalling, exposed rebar excluded: spalling_area_includes_rebar = false, as the masks \
    class rebar first), rebar_length_m (exposed main bars and ties, centre lines; ties between the \
    outer bars' centre lines, crossings counted in both), rebar_area_m2, crack_polyline_length_m \
    and spall_outline_area_m2 (the generated shapes in full, wherever they lie), region counts. \
    `regions`: one per crack (main crack, branches and later extensions), spall, and spall's \
    exposed bars, with an id stable across the surveys, class, facade, component (the \
    truth/components name and id carrying most of it), centroid (metres, world = twin frame), \
    length_m / polyline_length_m / width_m (mean) / area_m2 / outline_area_m2 as they apply, \
    spall (rebar: its spall's id), first_survey and new (absent in survey 1; growth is not new). \
    Cracks lie on faces parallel to their facade, so lengths in facade (u, v) are 3D lengths.";

/// The quantities of `state` (survey `survey`); with `previous` (survey 1's state), regions
/// whose id it lacks are new.
pub fn measure(
    building: &Building,
    geometry: &Geometry,
    state: &DamageState,
    previous: Option<&DamageState>,
    survey: u32,
) -> Quantities {
    let old_ids = previous.map(region_ids).unwrap_or_default();
    let mut crack_groups: BTreeMap<u32, (usize, Vec<&Crack>)> = BTreeMap::new();
    for (f, cracks) in state.cracks.iter().enumerate() {
        for c in cracks {
            crack_groups
                .entry(c.region)
                .or_insert((f, Vec::new()))
                .1
                .push(c);
        }
    }
    let mut jobs: Vec<Job> = crack_groups
        .into_iter()
        .map(|(id, (facade, cracks))| Job::Crack { id, facade, cracks })
        .collect();
    for (i, sp) in state.spalls.iter().enumerate() {
        jobs.push(Job::Spall(i));
        if let Some(rebar) = &sp.rebar {
            jobs.push(Job::Rebar(i, rebar));
        }
    }
    let meter = Meter {
        building,
        geometry,
        state,
    };
    let mut regions: Vec<Region> = jobs.par_iter().map(|job| meter.region(job)).collect();
    regions.sort_by_key(|r| r.id);

    let mut totals = Totals::default();
    let (mut crack, mut spall, mut rebar, mut rebar_area, mut polyline, mut outline) =
        (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for r in &mut regions {
        if survey >= 2 && !old_ids.contains(&r.id) {
            r.first_survey = survey;
            r.new = true;
            totals.new_regions += 1;
        }
        let get = |v: Option<f32>| v.unwrap_or(0.0) as f64;
        match DamageClass::from_id(&r.class) {
            Some(DamageClass::Crack) => {
                totals.cracks += 1;
                crack += get(r.length_m);
                polyline += get(r.polyline_length_m);
            }
            Some(DamageClass::Spalling) => {
                totals.spalls += 1;
                spall += get(r.area_m2);
                outline += get(r.outline_area_m2);
            }
            Some(DamageClass::Rebar) => {
                totals.rebar += 1;
                rebar += get(r.length_m);
                rebar_area += get(r.area_m2);
            }
            // Every region is made with a class id just above.
            None => {}
        }
    }
    totals.crack_length_m = crack as f32;
    totals.spalling_area_m2 = spall as f32;
    totals.rebar_length_m = rebar as f32;
    totals.rebar_area_m2 = rebar_area as f32;
    totals.crack_polyline_length_m = polyline as f32;
    totals.spall_outline_area_m2 = outline as f32;
    Quantities {
        survey,
        frame: "world (= twin, survey 1) frame: metres, z up".to_string(),
        spalling_area_includes_rebar: false,
        totals,
        regions,
    }
}

/// Every region id of a state (cracks, spalls, exposed bars).
fn region_ids(state: &DamageState) -> BTreeSet<u32> {
    let cracks = state.cracks.iter().flatten().map(|c| c.region);
    let spalls = state.spalls.iter().map(|s| s.id);
    let rebar = state
        .spalls
        .iter()
        .filter_map(|s| s.rebar.as_ref().map(|r| r.id));
    cracks.chain(spalls).chain(rebar).collect()
}

pub fn write(path: &Path, quantities: &Quantities) -> Result<(), SynthError> {
    super::write::json(path, quantities)
}

enum Job<'a> {
    Crack {
        id: u32,
        facade: usize,
        cracks: Vec<&'a Crack>,
    },
    Spall(usize),
    Rebar(usize, &'a Rebar),
}

/// Length or area on the surface, with what is needed for the centroid, mean width and component.
#[derive(Default)]
struct Tally {
    amount: f64,
    width: f64,
    position: DVec3,
    by_component: [f64; Component::ALL.len()],
}

impl Tally {
    fn add(&mut self, amount: f32, position: Vec3, component: Component, width: f32) {
        let a = amount as f64;
        self.amount += a;
        self.width += a * width as f64;
        self.position += a * position.as_dvec3();
        self.by_component[component.id() as usize] += a;
    }

    fn centroid(&self, fallback: Vec3) -> [f32; 3] {
        if self.amount > 0.0 {
            (self.position / self.amount).as_vec3().to_array()
        } else {
            fallback.to_array()
        }
    }

    fn mean_width(&self) -> Option<f32> {
        (self.amount > 0.0).then(|| (self.width / self.amount) as f32)
    }

    /// The component with the largest share (the lower id on a tie), if any.
    fn component(&self) -> Option<Component> {
        let mut best: Option<(usize, f64)> = None;
        for (i, &a) in self.by_component.iter().enumerate() {
            if a > best.map_or(0.0, |b| b.1) {
                best = Some((i, a));
            }
        }
        best.map(|(i, _)| Component::ALL[i])
    }
}

struct Meter<'a> {
    building: &'a Building,
    geometry: &'a Geometry,
    state: &'a DamageState,
}

impl Meter<'_> {
    fn region(&self, job: &Job) -> Region {
        match job {
            Job::Crack { id, facade, cracks } => self.crack(*id, *facade, cracks),
            Job::Spall(i) => self.spall(*i),
            Job::Rebar(i, rebar) => self.rebar(*i, rebar),
        }
    }

    /// Tallies `p` when it is classed `class` and lies on a damage-carrying surface.
    fn sample(
        &self,
        tally: &mut Tally,
        facade: usize,
        p: Vec2,
        class: DamageClass,
        amount: f32,
        width: f32,
    ) {
        if self.state.eval(facade, p, 0.0).class != Some(class) {
            return;
        }
        if let Some((pos, component)) = damage_surface(self.building, self.geometry, facade, p) {
            tally.add(amount, pos, component, width);
        }
    }

    fn on_plane(&self, facade: usize, p: Vec2) -> Vec3 {
        let fa = &self.building.facades[facade];
        fa.point(p.x, p.y, fa.offset)
    }

    fn crack(&self, id: u32, facade: usize, cracks: &[&Crack]) -> Region {
        let mut tally = Tally::default();
        let mut polyline = 0.0f64;
        let mut vertices = Vec2::ZERO;
        let mut count = 0usize;
        for c in cracks {
            vertices += c.points.iter().copied().sum::<Vec2>();
            count += c.points.len();
            for k in 1..c.points.len() {
                let (a, b) = (c.points[k - 1], c.points[k]);
                let (wa, wb) = (c.widths[k - 1], c.widths[k]);
                let len = (b - a).length();
                polyline += len as f64;
                let n = ((len / LINE_STEP).ceil() as usize).max(1);
                for j in 0..n {
                    let t = (j as f32 + 0.5) / n as f32;
                    let w = wa + (wb - wa) * t;
                    self.sample(
                        &mut tally,
                        facade,
                        a.lerp(b, t),
                        DamageClass::Crack,
                        len / n as f32,
                        w,
                    );
                }
            }
        }
        let fallback = self.on_plane(facade, vertices / count.max(1) as f32);
        Region {
            length_m: Some(tally.amount as f32),
            polyline_length_m: Some(polyline as f32),
            width_m: tally.mean_width(),
            ..region(id, DamageClass::Crack, facade, &tally, fallback)
        }
    }

    /// A cell inside several spalls belongs to the first of them (older spalls come first).
    fn spall(&self, index: usize) -> Region {
        let spalls = &self.state.spalls;
        let sp = &spalls[index];
        let earlier: Vec<&Spall> = spalls[..index]
            .iter()
            .filter(|s| s.facade == sp.facade)
            .collect();
        let mut tally = Tally::default();
        let area = AREA_CELL * AREA_CELL;
        for p in cells(sp.centre, BOUNDARY_MAX * sp.radius, AREA_CELL) {
            if sp.contains(p, 1.0) && !earlier.iter().any(|s| s.contains(p, 1.0)) {
                self.sample(&mut tally, sp.facade, p, DamageClass::Spalling, area, 0.0);
            }
        }
        let outline = polar_area(|dir| sp.boundary(dir));
        Region {
            area_m2: Some(tally.amount as f32),
            outline_area_m2: Some(outline as f32),
            ..region(
                sp.id,
                DamageClass::Spalling,
                sp.facade,
                &tally,
                self.on_plane(sp.facade, sp.centre),
            )
        }
    }

    /// The bars exposed in a spall's core: area on the grid, length along the bar centre lines
    /// (main bars across the core, ties between the outer main bars).
    fn rebar(&self, index: usize, rebar: &Rebar) -> Region {
        let spalls = &self.state.spalls;
        let sp = &spalls[index];
        let earlier: Vec<&Spall> = spalls[..index]
            .iter()
            .filter(|s| s.facade == sp.facade && s.rebar.is_some())
            .collect();
        let owned = |p: Vec2| {
            sp.contains(p, REBAR_CORE) && !earlier.iter().any(|s| s.contains(p, REBAR_CORE))
        };
        let reach = BOUNDARY_MAX * REBAR_CORE * sp.radius;
        let mut area = Tally::default();
        for p in cells(sp.centre, reach, AREA_CELL).filter(|&p| owned(p)) {
            self.sample(
                &mut area,
                sp.facade,
                p,
                DamageClass::Rebar,
                AREA_CELL * AREA_CELL,
                0.0,
            );
        }
        // Facade point of (across, along) coordinates.
        let point = |across: f32, along: f32| {
            if rebar.vertical {
                Vec2::new(across, along)
            } else {
                Vec2::new(along, across)
            }
        };
        let c_along = if rebar.vertical {
            sp.centre.y
        } else {
            sp.centre.x
        };
        let mut length = Tally::default();
        let steps = (2.0 * reach / LINE_STEP).ceil() as usize;
        for &bar in &rebar.bars {
            for k in 0..steps {
                let along = c_along - reach + (k as f32 + 0.5) * LINE_STEP;
                let p = point(bar, along);
                if owned(p) {
                    self.sample(
                        &mut length,
                        sp.facade,
                        p,
                        DamageClass::Rebar,
                        LINE_STEP,
                        2.0 * BAR_HALF,
                    );
                }
            }
        }
        let lo = rebar.bars.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = rebar.bars.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let first = ((c_along - reach) / rebar.tie_spacing).ceil() as i64;
        let last = ((c_along + reach) / rebar.tie_spacing).floor() as i64;
        let tie_steps = ((hi - lo) / LINE_STEP).ceil().max(1.0) as usize;
        let tie_step = (hi - lo) / tie_steps as f32;
        for t in first..=last {
            let along = t as f32 * rebar.tie_spacing;
            for k in 0..tie_steps {
                let p = point(lo + (k as f32 + 0.5) * tie_step, along);
                if owned(p) {
                    // Ties are 0.7 of a main bar (`DamageState::eval`).
                    self.sample(
                        &mut length,
                        sp.facade,
                        p,
                        DamageClass::Rebar,
                        tie_step,
                        1.4 * BAR_HALF,
                    );
                }
            }
        }
        Region {
            length_m: Some(length.amount as f32),
            width_m: length.mean_width(),
            area_m2: Some(area.amount as f32),
            spall: Some(sp.id),
            ..region(
                rebar.id,
                DamageClass::Rebar,
                sp.facade,
                &length,
                self.on_plane(sp.facade, sp.centre),
            )
        }
    }
}

/// The fields every region has; survey 1 until `measure` says otherwise.
fn region(id: u32, class: DamageClass, facade: usize, tally: &Tally, fallback: Vec3) -> Region {
    let component = tally.component();
    Region {
        id,
        class: class.id().to_string(),
        facade,
        component: component.map(|c| c.name().to_string()),
        component_id: component.map(|c| c.id()),
        centroid: tally.centroid(fallback),
        length_m: None,
        polyline_length_m: None,
        width_m: None,
        area_m2: None,
        outline_area_m2: None,
        spall: None,
        first_survey: 1,
        new: false,
    }
}
