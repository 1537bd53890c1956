//! Where damage goes: the planes enough photos see, a spot on one of them that its points
//! cover and at least two photos see, turned and sized in metres; then the decal's colours
//! moved to the facade under it (per-channel mean and standard deviation, from the photo that
//! sees the spot most squarely).

use std::collections::BTreeMap;

use glam::DVec3;

use crate::scene::RgbImage;
use crate::scene::load::load_image;

use super::decal::{ColourStats, Decal, Placement, SpallShape, crack_decal, spall_decal};
use super::params::StampError;
use super::planes::Plane;
use super::render::{Lens, hidden};
use super::sources::{SourceCrack, SourcePair, load_crack, load_texture};

/// A photo of the capture: its lens at the stored size and its file.
pub struct Photo {
    pub lens: Lens,
    pub path: std::path::PathBuf,
}

/// Inlier points a photo must see for the plane to count as seen by it.
const MIN_POINTS_SEEN: usize = 8;

/// Turns each plane's normal towards most of the photos that see it, and counts those photos.
pub fn orient_and_count(planes: &mut [Plane], photos: &[Photo]) -> Vec<usize> {
    planes
        .iter_mut()
        .map(|plane| {
            let centroid =
                plane.inliers.iter().copied().sum::<DVec3>() / plane.inliers.len().max(1) as f64;
            let facing: f64 = photos
                .iter()
                .map(|p| plane.normal.dot(p.lens.origin() - centroid).signum())
                .sum();
            if facing < 0.0 {
                plane.normal = -plane.normal;
                plane.offset = -plane.offset;
                plane.v = plane.normal.cross(plane.u);
                let (nx, ny) = plane.grid_size;
                // v flipped: the grid's rows run the other way.
                let mut flipped = vec![false; nx * ny];
                for j in 0..ny {
                    for i in 0..nx {
                        flipped[(ny - 1 - j) * nx + i] = plane.occupied[j * nx + i];
                    }
                }
                plane.occupied = flipped;
                plane.grid_origin.1 = -(plane.grid_origin.1 + ny as f64 * plane.cell);
            }
            photos
                .iter()
                .filter(|photo| {
                    let seen = plane
                        .inliers
                        .iter()
                        .filter(|p| {
                            plane.normal.dot(photo.lens.origin() - **p) > 0.0
                                && inside(&photo.lens, **p)
                        })
                        .count();
                    seen >= MIN_POINTS_SEEN
                })
                .count()
        })
        .collect()
}

fn inside(lens: &Lens, p: DVec3) -> bool {
    let (w, h) = lens.size();
    lens.project(p)
        .is_some_and(|q| q.x >= 0.0 && q.y >= 0.0 && q.x < w as f64 && q.y < h as f64)
}

/// Whether photo `lens` sees point `p` of plane `plane` (in the image, in front of the plane's
/// face, no nearer bounded plane in the way).
pub fn sees(lens: &Lens, p: DVec3, plane: usize, planes: &[Plane]) -> bool {
    if !inside(lens, p) || planes[plane].normal.dot(lens.origin() - p) <= 0.0 {
        return false;
    }
    let origin = lens.origin();
    let direction = (p - origin).normalize();
    !hidden(origin, direction, (p - origin).length(), plane, planes)
}

/// What a placement needs: the capture, its usable planes, the sources, the decals so far.
pub struct Placer<'a> {
    pub photos: &'a [Photo],
    pub planes: &'a [Plane],
    /// Indices of planes enough photos see, and their inlier counts (the draw's weights).
    pub usable: Vec<usize>,
    pub pairs: &'a [SourcePair],
    pub metres_per_unit: f64,
    pub rng: fastrand::Rng,
    pub placed: Vec<Decal>,
    cracks: BTreeMap<usize, Option<SourceCrack>>,
    textures: BTreeMap<usize, RgbImage>,
}

/// Tries per decal before giving up on it.
const TRIES: usize = 200;

/// What to place.
#[derive(Clone, Debug)]
pub enum Kind {
    Crack {
        length_m: f64,
        min_width_m: f64,
        survey1_share: f64,
    },
    Spall {
        shape: SpallShape,
    },
}

impl<'a> Placer<'a> {
    pub fn new(
        photos: &'a [Photo],
        planes: &'a [Plane],
        usable: Vec<usize>,
        pairs: &'a [SourcePair],
        metres_per_unit: f64,
        rng: fastrand::Rng,
    ) -> Placer<'a> {
        Placer {
            photos,
            planes,
            usable,
            pairs,
            metres_per_unit,
            rng,
            placed: Vec::new(),
            cracks: BTreeMap::new(),
            textures: BTreeMap::new(),
        }
    }

    fn pick_plane(&mut self) -> usize {
        let total: usize = self
            .usable
            .iter()
            .map(|&i| self.planes[i].inliers.len())
            .sum();
        let mut pick = self.rng.usize(..total.max(1));
        for &i in &self.usable {
            let n = self.planes[i].inliers.len();
            if pick < n {
                return i;
            }
            pick -= n;
        }
        self.usable[0]
    }

    fn source_crack(&mut self) -> Result<Option<SourceCrack>, StampError> {
        for _ in 0..self.pairs.len().max(1) * 2 {
            let k = self.rng.usize(..self.pairs.len());
            if !self.cracks.contains_key(&k) {
                let crack = load_crack(&self.pairs[k])?;
                self.cracks.insert(k, crack);
            }
            if let Some(Some(crack)) = self.cracks.get(&k) {
                return Ok(Some(crack.clone()));
            }
        }
        Ok(None)
    }

    fn texture(&mut self) -> Result<RgbImage, StampError> {
        let k = self.rng.usize(..self.pairs.len());
        if !self.textures.contains_key(&k) {
            let texture = load_texture(&self.pairs[k])?;
            self.textures.insert(k, texture);
        }
        Ok(self.textures[&k].clone())
    }

    /// Places one decal; `Ok(false)` when no spot was found in `TRIES` draws.
    pub fn place(&mut self, id: u32, kind: &Kind, first_survey: u32) -> Result<bool, StampError> {
        let crack_source = match kind {
            Kind::Crack { .. } => match self.source_crack()? {
                Some(source) => Some(source),
                None => return Ok(false),
            },
            Kind::Spall { .. } => None,
        };
        let texture = match (kind, self.pairs.is_empty()) {
            (Kind::Spall { .. }, false) => Some(self.texture()?),
            (Kind::Spall { .. }, true) => Some(RgbImage::filled(8, 8, [0.5; 3])),
            _ => None,
        };
        for _ in 0..TRIES {
            let plane_index = self.pick_plane();
            let plane = &self.planes[plane_index];
            let seed_point = plane.inliers[self.rng.usize(..plane.inliers.len())];
            let (a, b) = plane.coords(seed_point);
            let centre = plane.point(a, b);
            let angle = match kind {
                Kind::Crack { .. } => self.rng.f64() * std::f64::consts::TAU,
                Kind::Spall { .. } => 0.0,
            };
            let placement = Placement {
                plane: plane_index,
                centre,
                plane_u: plane.u,
                plane_v: plane.v,
                angle,
                metres_per_unit: self.metres_per_unit,
            };
            let decal = match (kind, &crack_source, &texture) {
                (
                    Kind::Crack {
                        length_m,
                        min_width_m,
                        survey1_share,
                    },
                    Some(source),
                    _,
                ) => {
                    let length = length_m * (0.6 + 0.4 * self.rng.f64());
                    let flip = self.rng.bool();
                    let shape = (length, *min_width_m, *survey1_share, flip);
                    crack_decal(id, source, &placement, shape, first_survey)
                }
                (Kind::Spall { shape }, _, Some(texture)) => {
                    spall_decal(id, shape, texture, &placement, first_survey)
                }
                _ => return Ok(false),
            };
            if !self.fits(&decal) {
                continue;
            }
            let seen_by: Vec<usize> = (0..self.photos.len())
                .filter(|&k| sees(&self.photos[k].lens, centre, plane_index, self.planes))
                .collect();
            if seen_by.len() < 2 {
                continue;
            }
            let mut decal = decal;
            let stats = self.facade_stats(&decal, &seen_by)?;
            decal.match_colours(stats);
            self.placed.push(decal);
            return Ok(true);
        }
        Ok(false)
    }

    /// The decal's outline lies on its plane's surface and clear of every decal placed.
    fn fits(&self, decal: &Decal) -> bool {
        let plane = &self.planes[decal.plane];
        let corners = decal.corners();
        let centre = decal.centre();
        let on_surface = corners
            .iter()
            .map(|c| centre + (*c - centre) * 0.8)
            .chain([centre])
            .all(|p| {
                let (a, b) = plane.coords(p);
                plane.covers(a, b)
            });
        let radius = |d: &Decal| (d.corners()[2] - d.corners()[0]).length() * 0.5;
        on_surface
            && self
                .placed
                .iter()
                .all(|d| (d.centre() - centre).length() > 0.7 * (radius(d) + radius(decal)))
    }

    /// The facade's colour statistics under the decal, in the photo that sees its centre most
    /// squarely.
    fn facade_stats(&self, decal: &Decal, seen_by: &[usize]) -> Result<ColourStats, StampError> {
        let plane = &self.planes[decal.plane];
        let centre = decal.centre();
        let squareness = |k: usize| {
            let lens = &self.photos[k].lens;
            plane.normal.dot((lens.origin() - centre).normalize())
        };
        let best = seen_by
            .iter()
            .copied()
            .max_by(|&a, &b| squareness(a).total_cmp(&squareness(b)))
            .unwrap_or(seen_by[0]);
        let photo = load_image(&self.photos[best].path)?;
        let lens = &self.photos[best].lens;
        let mut samples = Vec::new();
        const GRID: usize = 24;
        for j in 0..GRID {
            for i in 0..GRID {
                let p = decal.origin
                    + decal.axis_u
                        * ((i as f64 + 0.5) / GRID as f64 * decal.width as f64 * decal.texel)
                    + decal.axis_v
                        * ((j as f64 + 0.5) / GRID as f64 * decal.height as f64 * decal.texel);
                if !sees(lens, p, decal.plane, self.planes) {
                    continue;
                }
                if let Some(q) = lens.project(p) {
                    let (x, y) = (q.x as u32, q.y as u32);
                    if x < photo.width && y < photo.height {
                        samples.push(photo.pixel(x, y));
                    }
                }
            }
        }
        Ok(ColourStats::of(samples.into_iter()).unwrap_or(ColourStats {
            mean: [0.5; 3],
            std: [0.05; 3],
        }))
    }
}
