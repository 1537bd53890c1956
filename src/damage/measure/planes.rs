//! The surfaces damage lies on: each damage Gaussian's local plane (principal axes of the
//! Gaussians around it), grouped into a few planes (facades, recesses, soffits) by consensus:
//! the plane that most damage Gaussians agree with is taken first, then the next among the rest.

use glam::{DMat3, DVec3, Vec3};
use kiddo::{KdTree, SquaredEuclidean};

/// A plane `normal · x = offset` and the damage Gaussians (seeds) measured on it.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfacePlane {
    pub normal: DVec3,
    pub offset: f64,
    pub seeds: Vec<u32>,
}

/// How seeds are grouped.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneConfig {
    /// Gaussians within this radius (metres) of a seed give its local plane.
    pub neighbourhood: f64,
    /// A seed agrees with a plane when its local normal is within this angle...
    pub max_angle_degrees: f64,
    /// ...and its centre within this distance (metres).
    pub max_offset: f64,
    /// Groups with fewer seeds join the nearest larger plane within `max_offset`.
    pub min_seeds: usize,
}

impl Default for PlaneConfig {
    fn default() -> Self {
        PlaneConfig {
            neighbourhood: 0.3,
            max_angle_degrees: 30.0,
            max_offset: 0.3,
            min_seeds: 20,
        }
    }
}

/// Most plane hypotheses tried per group (evenly spaced over the seeds not yet grouped).
const HYPOTHESES: usize = 200;

/// Groups `seeds` (indices into `means`) into planes, largest first.
pub fn surface_planes(means: &[Vec3], seeds: &[u32], config: &PlaneConfig) -> Vec<SurfacePlane> {
    if seeds.is_empty() {
        return Vec::new();
    }
    let mut tree: KdTree<f64, 3> = KdTree::with_capacity(means.len());
    for (g, m) in means.iter().enumerate() {
        tree.add(&m.as_dvec3().to_array(), g as u64);
    }
    let r2 = config.neighbourhood * config.neighbourhood;
    let normals: Vec<DVec3> = seeds
        .iter()
        .map(|&s| {
            let centre = means[s as usize].as_dvec3();
            let near = tree.within_unsorted::<SquaredEuclidean>(&centre.to_array(), r2);
            let points: Vec<DVec3> = near
                .iter()
                .map(|n| means[n.item as usize].as_dvec3())
                .collect();
            local_normal(&points)
        })
        .collect();
    let positions: Vec<DVec3> = seeds
        .iter()
        .map(|&s| means[s as usize].as_dvec3())
        .collect();
    let cos_max = config.max_angle_degrees.to_radians().cos();
    let agrees = |i: usize, normal: DVec3, offset: f64| {
        normals[i].dot(normal).abs() >= cos_max
            && (positions[i].dot(normal) - offset).abs() < config.max_offset
    };

    let mut left: Vec<bool> = vec![true; seeds.len()];
    let mut groups: Vec<(DVec3, f64, Vec<usize>)> = Vec::new();
    while left.iter().any(|&l| l) {
        let remaining: Vec<usize> = (0..seeds.len()).filter(|&i| left[i]).collect();
        let step = remaining.len().div_ceil(HYPOTHESES).max(1);
        let mut best: Option<(usize, usize)> = None;
        for &h in remaining.iter().step_by(step) {
            let (normal, offset) = (normals[h], positions[h].dot(normals[h]));
            let support = remaining
                .iter()
                .filter(|&&i| agrees(i, normal, offset))
                .count();
            if best.is_none_or(|(_, b)| support > b) {
                best = Some((h, support));
            }
        }
        let Some((h, _)) = best else { break };
        // Refine: the mean of the agreeing normals (sign-aligned), the median offset.
        let first: Vec<usize> = remaining
            .iter()
            .copied()
            .filter(|&i| agrees(i, normals[h], positions[h].dot(normals[h])))
            .collect();
        let summed: DVec3 = first
            .iter()
            .map(|&i| normals[i] * normals[i].dot(normals[h]).signum())
            .sum();
        let normal = summed.try_normalize().unwrap_or(normals[h]);
        let mut offsets: Vec<f64> = first.iter().map(|&i| positions[i].dot(normal)).collect();
        offsets.sort_by(f64::total_cmp);
        let offset = offsets[offsets.len() / 2];
        let mut members: Vec<usize> = remaining
            .iter()
            .copied()
            .filter(|&i| agrees(i, normal, offset))
            .collect();
        if members.is_empty() {
            members.push(h);
        }
        for &i in &members {
            left[i] = false;
        }
        groups.push((normal, offset, members));
    }

    // Small groups (seeds with a poor local normal: corners, edges) join the nearest large plane.
    let (mut large, small): (Vec<_>, Vec<_>) = groups
        .into_iter()
        .partition(|g| g.2.len() >= config.min_seeds);
    for (normal, offset, members) in small {
        let mut orphans = Vec::new();
        for i in members {
            let nearest = large
                .iter_mut()
                .map(|g| ((positions[i].dot(g.0) - g.1).abs(), g))
                .filter(|(d, _)| *d < config.max_offset)
                .min_by(|a, b| a.0.total_cmp(&b.0));
            match nearest {
                Some((_, g)) => g.2.push(i),
                None => orphans.push(i),
            }
        }
        if !orphans.is_empty() {
            large.push((normal, offset, orphans));
        }
    }
    large.sort_by_key(|g| std::cmp::Reverse(g.2.len()));
    large
        .into_iter()
        .map(|(normal, offset, members)| {
            let mut seeds: Vec<u32> = members.into_iter().map(|i| seeds[i]).collect();
            seeds.sort_unstable();
            let (normal, offset) = refit(means, &seeds, normal, offset, config);
            SurfacePlane {
                normal,
                offset,
                seeds,
            }
        })
        .collect()
}

/// The plane of the surface under a group's seeds: every Gaussian within `max_offset` of the
/// seeds' plane and beside its seeds (their extent plus `neighbourhood`), fitted twice. The
/// seeds alone fix a plane poorly (a facade's cracks are lines; averaged local normals tilt by a
/// few degrees, a decimetre across a facade), the wall's own Gaussians well. Kept only where
/// they are flat and within `max_angle_degrees` of the seeds' plane.
fn refit(
    means: &[Vec3],
    seeds: &[u32],
    normal: DVec3,
    offset: f64,
    config: &PlaneConfig,
) -> (DVec3, f64) {
    let (mut n, mut d) = (normal, offset);
    let axis_u = n.any_orthonormal_vector();
    let axis_v = n.cross(axis_u);
    let (mut lo, mut hi) = (
        glam::DVec2::splat(f64::INFINITY),
        glam::DVec2::splat(f64::NEG_INFINITY),
    );
    for &g in seeds {
        let p = means[g as usize].as_dvec3();
        let uv = glam::DVec2::new(p.dot(axis_u), p.dot(axis_v));
        lo = lo.min(uv);
        hi = hi.max(uv);
    }
    let (lo, hi) = (lo - config.neighbourhood, hi + config.neighbourhood);
    for _ in 0..2 {
        let points: Vec<DVec3> = means
            .iter()
            .map(|m| m.as_dvec3())
            .filter(|p| {
                let uv = glam::DVec2::new(p.dot(axis_u), p.dot(axis_v));
                (p.dot(n) - d).abs() < config.max_offset && uv.cmpge(lo).all() && uv.cmple(hi).all()
            })
            .collect();
        let Some((fitted, flatness)) = plane_fit(&points) else {
            break;
        };
        let cos_max = config.max_angle_degrees.to_radians().cos();
        if !(fitted.dot(normal).abs() >= cos_max && flatness < MAX_FLATNESS) {
            break;
        }
        n = fitted * fitted.dot(normal).signum();
        let mut offsets: Vec<f64> = points.iter().map(|p| p.dot(n)).collect();
        offsets.sort_by(f64::total_cmp);
        d = offsets[offsets.len() / 2];
    }
    (n, d)
}

/// A refit is a plane when its least spread is at most this fraction of its middle one.
const MAX_FLATNESS: f64 = 0.05;

/// The least-spread direction of `points` and the ratio of its spread to the middle one.
fn plane_fit(points: &[DVec3]) -> Option<(DVec3, f64)> {
    if points.len() < 3 {
        return None;
    }
    let mean = points.iter().sum::<DVec3>() / points.len() as f64;
    let mut cov = DMat3::ZERO;
    for p in points {
        let d = *p - mean;
        cov += DMat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    let n = smallest_eigenvector(cov);
    let least = n.dot(cov * n);
    let u = n.any_orthonormal_vector();
    let v = n.cross(u);
    // The middle eigenvalue is at most the larger in-plane spread and at least the smaller.
    let middle = (u.dot(cov * u)).min(v.dot(cov * v));
    (middle > 0.0).then(|| (n, least / middle))
}

/// The direction of least spread of `points` (+z when there are too few to tell).
fn local_normal(points: &[DVec3]) -> DVec3 {
    if points.len() < 3 {
        return DVec3::Z;
    }
    let mean = points.iter().sum::<DVec3>() / points.len() as f64;
    let mut cov = DMat3::ZERO;
    for p in points {
        let d = *p - mean;
        cov += DMat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    smallest_eigenvector(cov)
}

/// The eigenvector of a symmetric 3×3 matrix with the smallest eigenvalue (cyclic Jacobi).
pub fn smallest_eigenvector(m: DMat3) -> DVec3 {
    let mut a = m.to_cols_array_2d();
    let mut v = DMat3::IDENTITY.to_cols_array_2d();
    for _ in 0..32 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        if off < 1e-24 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-30 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A <- Jᵀ A J, V <- V J (a is symmetric, indexed [col][row] = [row][col]).
            for column in &mut a {
                let (akp, akq) = (column[p], column[q]);
                column[p] = c * akp - s * akq;
                column[q] = s * akp + c * akq;
            }
            let (column_p, column_q) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = c * column_p[k] - s * column_q[k];
                a[q][k] = s * column_p[k] + c * column_q[k];
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let k = (0..3)
        .min_by(|&i, &j| a[i][i].total_cmp(&a[j][j]))
        .unwrap_or(2);
    DVec3::new(v[0][k], v[1][k], v[2][k]).normalize_or(DVec3::Z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_finds_the_normal_of_a_tilted_plane() {
        let normal = DVec3::new(0.3, -0.9, 0.2).normalize();
        let u = normal.any_orthonormal_vector();
        let w = normal.cross(u);
        let points: Vec<DVec3> = (0..100)
            .map(|i| {
                u * (i % 10) as f64 + w * (i / 10) as f64 * 0.7 + normal * 0.01 * (i % 3) as f64
            })
            .collect();
        let n = local_normal(&points);
        assert!(n.dot(normal).abs() > 0.999, "{n} vs {normal}");
    }

    #[test]
    fn two_walls_give_two_planes() {
        // A wall at y = 0 and one at x = 5, Gaussians every 5 cm; seeds on both.
        let mut means = Vec::new();
        for i in 0..60 {
            for j in 0..40 {
                means.push(Vec3::new(i as f32 * 0.05, 0.0, j as f32 * 0.05));
                means.push(Vec3::new(5.0, 0.5 + i as f32 * 0.05, j as f32 * 0.05));
            }
        }
        let seeds: Vec<u32> = (0..means.len() as u32).step_by(7).collect();
        let planes = surface_planes(&means, &seeds, &PlaneConfig::default());
        assert_eq!(planes.len(), 2, "{planes:?}");
        let y_wall = planes.iter().find(|p| p.normal.y.abs() > 0.99).unwrap();
        assert!(y_wall.offset.abs() < 0.01);
        assert_eq!(
            planes.iter().map(|p| p.seeds.len()).sum::<usize>(),
            seeds.len()
        );
    }
}
