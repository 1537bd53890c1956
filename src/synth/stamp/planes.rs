//! The capture's surfaces: planes fitted to its sparse points by sequential RANSAC, each bounded
//! by the cells of a grid on the plane that hold its inliers (dilated to close the gaps between
//! SfM points on plain wall). These planes are where damage is placed and what occludes it.

use glam::{DVec3, Vec3};

use super::params::rng;

/// A bounded plane: `normal · x = offset`, with an in-plane basis and its occupied cells.
#[derive(Clone, Debug, PartialEq)]
pub struct Plane {
    pub normal: DVec3,
    pub offset: f64,
    /// In-plane unit axes: `u` horizontal (across the capture's up), `v = normal × u`.
    pub u: DVec3,
    pub v: DVec3,
    /// Grid origin (in (u, v) coordinates), cell size (model units) and occupancy.
    pub grid_origin: (f64, f64),
    pub cell: f64,
    pub grid_size: (usize, usize),
    pub occupied: Vec<bool>,
    /// The inlier distance it was fitted with (model units).
    pub tolerance: f64,
    /// The inlier points (model frame).
    pub inliers: Vec<DVec3>,
}

/// Cells along the longer side of a plane's grid at most (coarser cells beyond).
const MAX_GRID_SIDE: usize = 400;

impl Plane {
    /// (u, v) coordinates of a point of the plane.
    pub fn coords(&self, p: DVec3) -> (f64, f64) {
        (p.dot(self.u), p.dot(self.v))
    }

    /// The point of the plane at (u, v).
    pub fn point(&self, a: f64, b: f64) -> DVec3 {
        self.normal * self.offset + self.u * a + self.v * b
    }

    /// Whether the plane point at (u, v) lies on the surface (an occupied cell).
    pub fn covers(&self, a: f64, b: f64) -> bool {
        let i = ((a - self.grid_origin.0) / self.cell).floor();
        let j = ((b - self.grid_origin.1) / self.cell).floor();
        if !(i >= 0.0 && j >= 0.0) {
            return false;
        }
        let (i, j) = (i as usize, j as usize);
        i < self.grid_size.0 && j < self.grid_size.1 && self.occupied[j * self.grid_size.0 + i]
    }

    /// Ray parameter `t` where `origin + t·direction` meets the plane, when in front.
    pub fn hit(&self, origin: DVec3, direction: DVec3) -> Option<f64> {
        let denom = self.normal.dot(direction);
        if denom.abs() < 1e-12 {
            return None;
        }
        let t = (self.offset - self.normal.dot(origin)) / denom;
        (t > 0.0).then_some(t)
    }
}

/// How planes are searched for.
#[derive(Clone, Copy, Debug)]
pub struct PlaneSearch {
    /// Inlier distance, model units.
    pub tolerance: f64,
    /// Cell of the occupancy grid, model units.
    pub cell: f64,
    pub min_inliers: usize,
    pub max_planes: usize,
    pub iterations: usize,
}

/// Sequential RANSAC: the plane with the most inliers, refitted to them by least squares, its
/// inliers removed, and again, until a plane has fewer than `min_inliers`. `up` (the capture's
/// mean camera up) orients each plane's `u` axis horizontally.
pub fn fit_planes(points: &[Vec3], up: DVec3, search: &PlaneSearch, seed: u64) -> Vec<Plane> {
    let mut rest: Vec<DVec3> = points.iter().map(|p| p.as_dvec3()).collect();
    let mut planes = Vec::new();
    let mut random = rng(seed, 0x504C_414E);
    while planes.len() < search.max_planes && rest.len() >= search.min_inliers.max(3) {
        let mut best: Option<(usize, DVec3, f64)> = None;
        for _ in 0..search.iterations {
            let a = rest[random.usize(..rest.len())];
            let b = rest[random.usize(..rest.len())];
            let c = rest[random.usize(..rest.len())];
            let n = (b - a).cross(c - a);
            if !(n.length() > 1e-12) {
                continue;
            }
            let n = n.normalize();
            let d = n.dot(a);
            let count = rest
                .iter()
                .filter(|p| (n.dot(**p) - d).abs() < search.tolerance)
                .count();
            if best.is_none_or(|(c, _, _)| count > c) {
                best = Some((count, n, d));
            }
        }
        let Some((count, n, d)) = best else { break };
        if count < search.min_inliers {
            break;
        }
        let (inliers, outliers): (Vec<DVec3>, Vec<DVec3>) = rest
            .iter()
            .partition(|p| (n.dot(**p) - d).abs() < search.tolerance);
        let (normal, offset) = least_squares_plane(&inliers).unwrap_or((n, d));
        rest = outliers;
        planes.push(bounded(normal, offset, up, inliers, search));
    }
    planes
}

/// The plane through the points' centroid normal to their least-spread direction.
fn least_squares_plane(points: &[DVec3]) -> Option<(DVec3, f64)> {
    if points.len() < 3 {
        return None;
    }
    let centroid = points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let mut cov = glam::DMat3::ZERO;
    for p in points {
        let d = *p - centroid;
        cov += glam::DMat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    let normal = smallest_eigenvector(cov)?;
    Some((normal, normal.dot(centroid)))
}

/// The eigenvector of a symmetric 3×3 matrix with the smallest eigenvalue: power iteration on
/// `trace·I − M`, whose largest eigenvalue that is.
fn smallest_eigenvector(m: glam::DMat3) -> Option<DVec3> {
    let shifted =
        glam::DMat3::from_diagonal(DVec3::splat(m.x_axis.x + m.y_axis.y + m.z_axis.z)) - m;
    let mut v = DVec3::new(0.577, 0.578, 0.576);
    for _ in 0..200 {
        let next = shifted * v;
        let length = next.length();
        if !(length > 1e-300) {
            return None;
        }
        v = next / length;
    }
    Some(v)
}

fn bounded(
    normal: DVec3,
    offset: f64,
    up: DVec3,
    inliers: Vec<DVec3>,
    search: &PlaneSearch,
) -> Plane {
    let cell = search.cell;
    // Horizontal in-plane axis; a plane facing up (the ground) takes any axis.
    let across = up.cross(normal);
    let u = if across.length() > 0.2 {
        across.normalize()
    } else {
        normal.any_orthonormal_vector()
    };
    let v = normal.cross(u);
    let coords: Vec<(f64, f64)> = inliers.iter().map(|p| (p.dot(u), p.dot(v))).collect();
    let min_a = coords.iter().map(|c| c.0).fold(f64::INFINITY, f64::min);
    let max_a = coords.iter().map(|c| c.0).fold(f64::NEG_INFINITY, f64::max);
    let min_b = coords.iter().map(|c| c.1).fold(f64::INFINITY, f64::min);
    let max_b = coords.iter().map(|c| c.1).fold(f64::NEG_INFINITY, f64::max);
    let cell = cell.max((max_a - min_a).max(max_b - min_b) / MAX_GRID_SIDE as f64);
    // One cell of margin each side for the dilation.
    let origin = (min_a - cell, min_b - cell);
    let nx = ((max_a - min_a) / cell) as usize + 3;
    let ny = ((max_b - min_b) / cell) as usize + 3;
    let mut hits = vec![false; nx * ny];
    for (a, b) in &coords {
        let i = ((a - origin.0) / cell) as usize;
        let j = ((b - origin.1) / cell) as usize;
        hits[j.min(ny - 1) * nx + i.min(nx - 1)] = true;
    }
    // Dilate by one cell: SfM points are sparse on plain wall.
    let mut occupied = vec![false; nx * ny];
    for j in 0..ny {
        for i in 0..nx {
            let near = (j.saturating_sub(1)..=(j + 1).min(ny - 1))
                .any(|jj| (i.saturating_sub(1)..=(i + 1).min(nx - 1)).any(|ii| hits[jj * nx + ii]));
            occupied[j * nx + i] = near;
        }
    }
    Plane {
        normal,
        offset,
        u,
        v,
        grid_origin: origin,
        cell,
        grid_size: (nx, ny),
        occupied,
        tolerance: search.tolerance,
        inliers,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_walls_are_found_with_their_normals() {
        let mut points = Vec::new();
        let mut r = fastrand::Rng::with_seed(3);
        for _ in 0..300 {
            // Wall x = 2 and wall y = -1, 1 cm noise, plus scattered outliers.
            points.push(Vec3::new(
                2.0 + 0.01 * (r.f32() - 0.5),
                r.f32() * 4.0,
                r.f32() * 3.0,
            ));
            points.push(Vec3::new(
                r.f32() * 4.0 - 2.0,
                -1.0 + 0.01 * (r.f32() - 0.5),
                r.f32() * 3.0,
            ));
        }
        for _ in 0..100 {
            points.push(Vec3::new(r.f32() * 6.0, r.f32() * 6.0, r.f32() * 6.0));
        }
        let search = PlaneSearch {
            tolerance: 0.03,
            cell: 0.25,
            min_inliers: 50,
            max_planes: 4,
            iterations: 300,
        };
        let planes = fit_planes(&points, DVec3::Z, &search, 1);
        assert!(planes.len() >= 2, "{} planes", planes.len());
        let normals: Vec<DVec3> = planes.iter().take(2).map(|p| p.normal.abs()).collect();
        assert!(normals.iter().any(|n| n.x > 0.999), "{normals:?}");
        assert!(normals.iter().any(|n| n.y > 0.999), "{normals:?}");
        // Horizontal u, and the walls' cells cover their middle but not far outside.
        let wall = planes.iter().find(|p| p.normal.x.abs() > 0.99).unwrap();
        assert!(wall.u.z.abs() < 1e-6);
        let (a, b) = wall.coords(DVec3::new(2.0, 2.0, 1.5));
        assert!(wall.covers(a, b));
        let (a, b) = wall.coords(DVec3::new(2.0, 9.0, 1.5));
        assert!(!wall.covers(a, b));
    }
}
