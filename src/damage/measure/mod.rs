//! Damage measured on the twin: regions per class with crack and rebar lengths, mean widths and
//! areas, in model units. The damage Gaussians (a class probability of at least one half, not
//! faint) are grouped by the surface plane they lie on (`planes`); each plane's labels are
//! splatted straight on (`surface_map`) at a photo's ground pixel size; a class's cells above
//! one half, joined across small gaps, are its regions; a region's length is its skeleton's
//! (`raster_ops`), its area its cells', its width their ratio. Spalling leaves out the rebar
//! in it, as the masks do.

pub mod planes;
pub mod raster_ops;
pub mod surface_map;
pub mod visibility;

use std::collections::BTreeSet;

use glam::{DVec2, DVec3};
use kiddo::{KdTree, SquaredEuclidean};
use serde::Serialize;

use crate::damage::DamageClass;
use crate::scene::Camera;
use crate::splats::Splats;
use crate::splats::model::{NO_SURVEY, sigmoid};
use planes::{PlaneConfig, SurfacePlane, surface_planes};
use raster_ops::{Bitmap, components, skeleton_length, thinned};
use surface_map::{PlaneFrame, SurfaceMap, surface_map};
use visibility::Occlusion;

/// How damage is measured (lengths in model units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasureConfig {
    /// A Gaussian, or a map cell's blended label, is damage of a class at this probability.
    pub threshold: f32,
    /// Fainter Gaussians do not seed planes.
    pub min_opacity: f32,
    /// Map cell: the ground size of a photo's pixel (1 cm on the demo building).
    pub cell: f64,
    /// Gaussians this far from a plane are splatted onto it.
    pub slab: f64,
    /// Border around a plane's damage.
    pub margin: f64,
    /// Cells of a class closer than this are one region.
    pub gap: f64,
    /// Regions of fewer cells are noise.
    pub min_cells: usize,
    /// Size of the cells regions are compared across surveys by.
    pub match_voxel: f64,
    /// Rays from the cameras to a plane's damage are sampled this often for occluders...
    pub ray_step: f64,
    /// ...which are the Gaussians centred within this of a sample.
    pub ray_reach: f64,
    pub planes: PlaneConfig,
}

impl Default for MeasureConfig {
    fn default() -> Self {
        MeasureConfig {
            threshold: 0.5,
            min_opacity: 0.1,
            cell: 0.01,
            slab: 0.3,
            margin: 0.1,
            gap: 0.05,
            min_cells: 10,
            match_voxel: 0.05,
            ray_step: 0.05,
            ray_reach: 0.1,
            planes: PlaneConfig::default(),
        }
    }
}

impl MeasureConfig {
    /// The metric defaults in a model of `metres_per_unit`.
    pub fn for_scale(metres_per_unit: f64) -> MeasureConfig {
        let d = MeasureConfig::default();
        let k = 1.0 / metres_per_unit;
        MeasureConfig {
            cell: d.cell * k,
            slab: d.slab * k,
            margin: d.margin * k,
            gap: d.gap * k,
            match_voxel: d.match_voxel * k,
            ray_step: d.ray_step * k,
            ray_reach: d.ray_reach * k,
            planes: PlaneConfig {
                neighbourhood: d.planes.neighbourhood * k,
                max_offset: d.planes.max_offset * k,
                ..d.planes
            },
            ..d
        }
    }
}

/// One connected piece of one class's damage on one plane.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MeasuredRegion {
    pub class: DamageClass,
    /// Index into `Measurement::planes`.
    pub plane: usize,
    /// Mean position of its cells (model frame).
    pub centroid: [f64; 3],
    /// Crack and rebar: skeleton length. None for spalling.
    pub length: Option<f64>,
    /// Area / length, where a length is measured.
    pub width: Option<f64>,
    pub area: f64,
    /// Damage Gaussians inside it.
    pub gaussians: usize,
    /// Earliest `damage_survey` among them (None: none tagged).
    pub first_survey: Option<u16>,
    /// Cells (`match_voxel` on a side) its surface passes through, to compare surveys.
    #[serde(skip)]
    pub voxels: BTreeSet<[i32; 3]>,
    /// Its damage Gaussians (model indices), to select it.
    #[serde(skip)]
    pub members: Vec<u32>,
}

/// A plane damage was measured on.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlaneSummary {
    /// Toward the cameras.
    pub normal: [f64; 3],
    pub offset: f64,
    pub seeds: usize,
    pub map_cells: [usize; 2],
}

#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Measurement {
    pub regions: Vec<MeasuredRegion>,
    pub planes: Vec<PlaneSummary>,
    pub seconds: f64,
}

impl Measurement {
    /// Total length (crack, rebar) or area (spalling) of a class; 0 (not −0) when it has no
    /// region.
    pub fn total_length(&self, class: DamageClass) -> f64 {
        plus_zero_sum(self.of(class).filter_map(|r| r.length))
    }

    pub fn total_area(&self, class: DamageClass) -> f64 {
        plus_zero_sum(self.of(class).map(|r| r.area))
    }

    pub fn of(&self, class: DamageClass) -> impl Iterator<Item = &MeasuredRegion> {
        self.regions.iter().filter(move |r| r.class == class)
    }
}

/// The sum from +0: `Iterator::sum` of no `f64`s is −0, which `study real` printed and wrote as
/// "measured -0.000" for a class the twin holds none of.
fn plus_zero_sum(values: impl Iterator<Item = f64>) -> f64 {
    values.fold(0.0, |sum, value| sum + value)
}

/// Most cells a plane's map may have (~100 MB with three label channels): a plane whose damage
/// spans more (a stray labelled Gaussian far out in its plane) is mapped with larger cells.
const MAX_MAP_CELLS: f64 = 8.0e6;

/// `cell`, or the larger cell that keeps the map of `[lower, upper]` within `MAX_MAP_CELLS`.
fn map_cell(lower: DVec2, upper: DVec2, cell: f64) -> f64 {
    let area = (upper - lower).max(DVec2::ZERO);
    cell.max((area.x * area.y / MAX_MAP_CELLS).sqrt())
}

/// Damage Gaussians: some class at `threshold` or more, opacity at `min_opacity` or more, not
/// hidden or deleted.
pub fn damage_seeds(splats: &Splats, config: &MeasureConfig) -> Vec<u32> {
    use crate::splats::model::state::{DELETED, HIDDEN};
    (0..splats.len())
        .filter(|&g| {
            splats.meta.state[g] & (HIDDEN | DELETED) == 0
                && sigmoid(splats.raw_opacities[g]) >= config.min_opacity
                && splats
                    .labels_of(g)
                    .iter()
                    .take(DamageClass::ALL.len())
                    .any(|&l| sigmoid(l) >= config.threshold)
        })
        .map(|g| g as u32)
        .collect()
}

/// Measures the damage of `splats`; `cameras` (the survey's photos) tell which side of each
/// surface was photographed.
pub fn measure_damage(splats: &Splats, cameras: &[Camera], config: &MeasureConfig) -> Measurement {
    let start = std::time::Instant::now();
    let mut out = Measurement::default();
    if splats.label_channels < DamageClass::ALL.len() {
        return out;
    }
    let seeds = damage_seeds(splats, config);
    let planes = surface_planes(&splats.means, &seeds, &config.planes);
    let occlusion = Occlusion::new(splats);
    for (index, plane) in planes.iter().enumerate() {
        let frame = facing_frame(splats, plane, cameras, &occlusion, config);
        let (lower, upper) = seed_bounds(splats, plane, &frame, config.margin);
        let map = surface_map(
            splats,
            frame,
            lower,
            upper,
            map_cell(lower, upper, config.cell),
            config.slab,
        );
        let owner = SeedOwner::new(splats, &planes, &frame, config.slab);
        for class in DamageClass::ALL {
            regions_of_class(splats, &map, index, class, &owner, config, &mut out.regions);
        }
        out.planes.push(PlaneSummary {
            normal: frame.toward_viewer.to_array(),
            offset: frame.toward_viewer.dot(frame.origin),
            seeds: plane.seeds.len(),
            map_cells: [map.width, map.height],
        });
    }
    out.seconds = start.elapsed().as_secs_f64();
    out
}

/// The plane's frame facing the photos that show its damage: each camera with the damage's
/// centre in its image votes for its side of the plane, weighted by how much of the centre it
/// sees through the twin (a photo from across the building has it in view, behind two walls)
/// and by cos² of its view ray to the normal over distance² (head-on and near counts most);
/// +normal without votes.
fn facing_frame(
    splats: &Splats,
    plane: &SurfacePlane,
    cameras: &[Camera],
    occlusion: &Occlusion,
    config: &MeasureConfig,
) -> PlaneFrame {
    let centre = plane
        .seeds
        .iter()
        .map(|&g| splats.means[g as usize].as_dvec3())
        .sum::<DVec3>()
        / plane.seeds.len().max(1) as f64;
    // The seeds' centre on the plane (a centroid of damage on two walls of a corner can float).
    let on_plane = centre - plane.normal * (centre.dot(plane.normal) - plane.offset);
    let vote: f64 = cameras
        .iter()
        .filter(|camera| camera.pixel_of(centre.as_vec3()).is_some())
        .map(|camera| {
            let eye = camera.position().as_dvec3();
            let d = eye - centre;
            let cos = d.normalize_or_zero().dot(plane.normal);
            let seen = occlusion.transmittance(
                eye,
                on_plane,
                config.slab,
                config.ray_step,
                config.ray_reach,
            );
            seen * cos.signum() * cos * cos / d.length_squared().max(1e-9)
        })
        .sum();
    PlaneFrame::new(plane.normal, plane.offset, !(vote < 0.0))
}

fn seed_bounds(
    splats: &Splats,
    plane: &SurfacePlane,
    frame: &PlaneFrame,
    margin: f64,
) -> (DVec2, DVec2) {
    let mut lower = DVec2::splat(f64::INFINITY);
    let mut upper = DVec2::splat(f64::NEG_INFINITY);
    for &g in &plane.seeds {
        let uv = frame.uv(splats.means[g as usize].as_dvec3());
        lower = lower.min(uv);
        upper = upper.max(uv);
    }
    (lower - margin, upper + margin)
}

/// Which plane's seed is nearest a map cell: a cell is measured on one plane only, where
/// planes overlap (a recess behind a facade, two groups of one wall).
struct SeedOwner {
    tree: KdTree<f64, 2>,
    plane_of: Vec<(usize, u32)>,
}

impl SeedOwner {
    fn new(splats: &Splats, planes: &[SurfacePlane], frame: &PlaneFrame, slab: f64) -> SeedOwner {
        let mut tree = KdTree::new();
        let mut plane_of = Vec::new();
        for (p, plane) in planes.iter().enumerate() {
            for &g in &plane.seeds {
                let mean = splats.means[g as usize].as_dvec3();
                if frame.height(mean).abs() < slab {
                    tree.add(&frame.uv(mean).to_array(), plane_of.len() as u64);
                    plane_of.push((p, g));
                }
            }
        }
        SeedOwner { tree, plane_of }
    }

    /// The plane and Gaussian of the seed nearest `uv`.
    fn nearest(&self, uv: DVec2) -> Option<(usize, u32)> {
        if self.plane_of.is_empty() {
            return None;
        }
        let hit = self.tree.nearest_one::<SquaredEuclidean>(&uv.to_array());
        Some(self.plane_of[hit.item as usize])
    }
}

fn regions_of_class(
    splats: &Splats,
    map: &SurfaceMap,
    plane_index: usize,
    class: DamageClass,
    owner: &SeedOwner,
    config: &MeasureConfig,
    regions: &mut Vec<MeasuredRegion>,
) {
    let k = class.channel();
    let rebar = DamageClass::Rebar.channel();
    let mut mask = Bitmap::new(map.width, map.height);
    let mut nearest_seed = vec![u32::MAX; map.width * map.height];
    for y in 0..map.height {
        for x in 0..map.width {
            let mut on = map.label(x, y, k) > config.threshold;
            if class == DamageClass::Spalling {
                on &= !(map.label(x, y, rebar) > config.threshold);
            }
            if !on {
                continue;
            }
            if let Some((p, g)) = owner.nearest(map.cell_uv(x, y))
                && p == plane_index
            {
                mask.data[y * map.width + x] = true;
                nearest_seed[y * map.width + x] = g;
            }
        }
    }
    let gap_cells = (config.gap / map.cell).round() as usize;
    let (label, count) = components(&mask.dilated(gap_cells));
    let mut cells_of: Vec<Vec<usize>> = vec![Vec::new(); count as usize];
    for (i, &on) in mask.data.iter().enumerate() {
        if on {
            cells_of[label[i] as usize - 1].push(i);
        }
    }
    for cells in cells_of.into_iter().filter(|c| c.len() >= config.min_cells) {
        regions.push(region_from_cells(
            splats,
            map,
            plane_index,
            class,
            &cells,
            &nearest_seed,
            config,
        ));
    }
}

fn region_from_cells(
    splats: &Splats,
    map: &SurfaceMap,
    plane_index: usize,
    class: DamageClass,
    cells: &[usize],
    nearest_seed: &[u32],
    config: &MeasureConfig,
) -> MeasuredRegion {
    let (w, cell) = (map.width, map.cell);
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    let mut uv_sum = DVec2::ZERO;
    let mut voxels = BTreeSet::new();
    let mut members = BTreeSet::new();
    for &i in cells {
        let (x, y) = (i % w, i / w);
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
        let uv = map.cell_uv(x, y);
        uv_sum += uv;
        let p = map.frame.point(uv) / config.match_voxel;
        voxels.insert([p.x.floor() as i32, p.y.floor() as i32, p.z.floor() as i32]);
        members.insert(nearest_seed[i]);
    }
    let length = (class != DamageClass::Spalling).then(|| {
        // The region's cells alone, with a one-cell border for the thinning.
        let mut crop = Bitmap::new(x1 - x0 + 3, y1 - y0 + 3);
        for &i in cells {
            let (x, y) = (i % w - x0 + 1, i / w - y0 + 1);
            crop.data[y * crop.width + x] = true;
        }
        skeleton_length(&thinned(&crop), config.gap / cell) * cell
    });
    let area = cells.len() as f64 * cell * cell;
    let members: Vec<u32> = members.into_iter().filter(|&g| g != u32::MAX).collect();
    let first_survey = members
        .iter()
        .map(|&g| splats.meta.damage_survey[g as usize])
        .filter(|&s| s != NO_SURVEY)
        .min();
    MeasuredRegion {
        class,
        plane: plane_index,
        centroid: map.frame.point(uv_sum / cells.len() as f64).to_array(),
        length,
        width: length.filter(|&l| l > 0.0).map(|l| area / l),
        area,
        gaussians: members.len(),
        first_survey,
        voxels,
        members,
    }
}
