//! Hull masks (the paper's §2.3): in each view, the convex hull of a set of Gaussians' 2D
//! footprints (their projected 3σ ellipses, not only their centres), dilated by a few pixels.
//! One hull per view as the paper draws it, or one per connected region of the set, which
//! leaves out the untouched surface between two distant pieces (two cracks). A focused run
//! renders and trains only inside these; views whose hulls are all empty or tiny are dropped.
//! Pure geometry: what the set is (damage, a block) is the caller's.

use glam::Vec2;
use kiddo::{ImmutableKdTree, SquaredEuclidean};

use crate::raster::Projected;
use crate::scene::Mask;
use crate::splats::Splats;

/// Points sampled on each footprint ellipse: with 12 the polygon through them lies within
/// 1 − cos(15°) = 3.4 % of the ellipse's radius inside it, well under the dilation.
const ELLIPSE_SAMPLES: usize = 12;

/// How hulls are drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HullConfig {
    /// Dilation in pixels (a disc): the margin that keeps the loss's SSIM window and the
    /// blurred edge of what is trained inside.
    pub dilate_px: f32,
    /// Hulls covering fewer pixels than this are dropped.
    pub min_area_px: usize,
    /// One hull per connected region instead of one per view.
    pub per_region: bool,
}

impl Default for HullConfig {
    fn default() -> Self {
        HullConfig {
            dilate_px: 4.0,
            min_area_px: 64,
            per_region: true,
        }
    }
}

/// One hull in one view: its polygon (before dilation) and its dilated mask, stored as the
/// window `[x0, x0 + mask.width) × [y0, y0 + mask.height)` of the image.
#[derive(Clone, Debug, PartialEq)]
pub struct Hull {
    pub polygon: Vec<Vec2>,
    pub x0: u32,
    pub y0: u32,
    pub mask: Mask,
    /// The region of the set it covers (0 when hulls are per view).
    pub region: u32,
}

impl Hull {
    /// Pixels inside.
    pub fn area(&self) -> usize {
        self.mask.count()
    }

    /// Paints this hull into a full-image mask.
    pub fn paint(&self, full: &mut Mask) {
        for y in 0..self.mask.height {
            for x in 0..self.mask.width {
                if self.mask.get(x, y) {
                    let (fx, fy) = (self.x0 + x, self.y0 + y);
                    full.data[(fy * full.width + fx) as usize] = 1;
                }
            }
        }
    }
}

/// Samples a Gaussian's 3σ footprint ellipse (from its projected mean and conic, the inverse of
/// its blurred 2D covariance) into `out`.
pub fn footprint_points(mean: Vec2, conic: glam::Vec3, out: &mut Vec<Vec2>) {
    let det_conic = conic.x * conic.z - conic.y * conic.y;
    if !(det_conic > 0.0) {
        return;
    }
    // Σ = conic⁻¹ = [[c, -b], [-b, a]] / det.
    let (a, b, c) = (
        conic.z / det_conic,
        -conic.y / det_conic,
        conic.x / det_conic,
    );
    let mid = 0.5 * (a + c);
    let disc = (mid * mid - (a * c - b * b)).max(0.0).sqrt();
    let (l1, l2) = (mid + disc, (mid - disc).max(0.0));
    // Eigenvector of l1: (b, l1 - a), or an axis when the covariance is diagonal.
    let e1 = if b.abs() > 1e-12 {
        Vec2::new(b, l1 - a).normalize()
    } else if a >= c {
        Vec2::X
    } else {
        Vec2::Y
    };
    let e2 = Vec2::new(-e1.y, e1.x);
    let (r1, r2) = (3.0 * l1.sqrt(), 3.0 * l2.sqrt());
    for i in 0..ELLIPSE_SAMPLES {
        let t = i as f32 / ELLIPSE_SAMPLES as f32 * std::f32::consts::TAU;
        out.push(mean + e1 * (r1 * t.cos()) + e2 * (r2 * t.sin()));
    }
}

/// The convex hull of `points`, counter-clockwise in image coordinates (y down), without
/// repeated or collinear vertices (Andrew's monotone chain).
pub fn convex_hull(points: &[Vec2]) -> Vec<Vec2> {
    let mut p: Vec<Vec2> = points.iter().copied().filter(|v| v.is_finite()).collect();
    p.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: Vec2, a: Vec2, b: Vec2| {
        f64::from(a.x - o.x) * f64::from(b.y - o.y) - f64::from(a.y - o.y) * f64::from(b.x - o.x)
    };
    let mut hull: Vec<Vec2> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &Vec2>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &v in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], v) <= 0.0
            {
                hull.pop();
            }
            hull.push(v);
        }
        hull.pop();
    }
    hull
}

/// The pixels (by centre) inside the convex `polygon` dilated by `dilate` pixels, clipped to a
/// `width × height` image; None when fewer than `min_area` remain.
pub fn rasterize_hull(
    polygon: &[Vec2],
    dilate: f32,
    width: u32,
    height: u32,
    min_area: usize,
) -> Option<(u32, u32, Mask)> {
    if polygon.is_empty() {
        return None;
    }
    let r = dilate.max(0.0);
    let (lo, hi) = polygon.iter().fold(
        (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY)),
        |(lo, hi), &v| (lo.min(v), hi.max(v)),
    );
    let clamp_x = |v: f32| v.clamp(0.0, width as f32) as u32;
    let clamp_y = |v: f32| v.clamp(0.0, height as f32) as u32;
    let (x0, x1) = (
        clamp_x((lo.x - r - 1.0).floor()),
        clamp_x((hi.x + r + 1.0).ceil()),
    );
    let (y0, y1) = (
        clamp_y((lo.y - r - 1.0).floor()),
        clamp_y((hi.y + r + 1.0).ceil()),
    );
    if x1 <= x0 || y1 <= y0 {
        return None;
    }
    let (w, h) = (x1 - x0, y1 - y0);
    let mut mask = Mask::empty(w, h);
    // The polygon itself, row by row: a convex polygon meets a row in one interval.
    for y in 0..h {
        let yc = (y0 + y) as f32 + 0.5;
        let (mut left, mut right) = (f32::INFINITY, f32::NEG_INFINITY);
        if polygon.len() < 3 {
            for v in polygon {
                if (v.y - yc).abs() <= 0.5 {
                    left = left.min(v.x);
                    right = right.max(v.x);
                }
            }
        }
        for i in 0..polygon.len() {
            let (a, b) = (polygon[i], polygon[(i + 1) % polygon.len()]);
            if (a.y <= yc && yc <= b.y) || (b.y <= yc && yc <= a.y) {
                let x = if (b.y - a.y).abs() < 1e-12 {
                    left = left.min(a.x.min(b.x));
                    a.x.max(b.x)
                } else {
                    a.x + (yc - a.y) / (b.y - a.y) * (b.x - a.x)
                };
                left = left.min(x);
                right = right.max(x);
            }
        }
        for x in 0..w {
            let xc = (x0 + x) as f32 + 0.5;
            if xc >= left && xc <= right {
                mask.data[(y * w + x) as usize] = 1;
            }
        }
    }
    // The dilation: a disc stamped at every polygon vertex and along every edge, plus the
    // polygon's boundary pixels (together they cover the Minkowski sum with the disc).
    if r > 0.0 {
        let stamp = |mask: &mut Mask, c: Vec2| {
            let (cx, cy) = (c.x - x0 as f32, c.y - y0 as f32);
            let ys = ((cy - r - 0.5).floor().max(0.0) as u32)
                ..((cy + r + 0.5).ceil().max(0.0) as u32).min(h);
            for y in ys {
                let dy = y as f32 + 0.5 - cy;
                let xs = ((cx - r - 0.5).floor().max(0.0) as u32)
                    ..((cx + r + 0.5).ceil().max(0.0) as u32).min(w);
                for x in xs {
                    let dx = x as f32 + 0.5 - cx;
                    if dx * dx + dy * dy <= r * r {
                        mask.data[(y * w + x) as usize] = 1;
                    }
                }
            }
        };
        // Along each edge, discs every half pixel leave no gap wider than 1/16 px.
        for i in 0..polygon.len() {
            let (a, b) = (polygon[i], polygon[(i + 1) % polygon.len()]);
            let steps = (a.distance(b) * 2.0).ceil().max(1.0) as usize;
            for s in 0..=steps {
                stamp(&mut mask, a.lerp(b, s as f32 / steps as f32));
            }
        }
    }
    let area = mask.count();
    (area >= min_area.max(1)).then_some((x0, y0, mask))
}

/// Connected regions: Gaussians `selected` whose centres chain within `radius` share a
/// region. Returns per selected Gaussian (same order) its region id, counting from 0.
pub fn regions(splats: &Splats, selected: &[u32], radius: f32) -> Vec<u32> {
    let n = selected.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    if n > 1 {
        let coords: Vec<[f32; 3]> = selected
            .iter()
            .map(|&g| splats.means[g as usize].to_array())
            .collect();
        let tree: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(&coords);
        for (i, c) in coords.iter().enumerate() {
            for nb in tree.within_unsorted::<SquaredEuclidean>(c, radius * radius) {
                let (a, b) = (find(&mut parent, i), find(&mut parent, nb.item as usize));
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    let mut ids = std::collections::HashMap::new();
    (0..n)
        .map(|i| {
            let root = find(&mut parent, i);
            let next = ids.len() as u32;
            *ids.entry(root).or_insert(next)
        })
        .collect()
}

/// The median distance of the `selected` Gaussians to their nearest selected neighbour: the
/// set's own density, the unit region radii are given in.
pub fn median_spacing(splats: &Splats, selected: &[u32]) -> f32 {
    if selected.len() < 2 {
        return 0.0;
    }
    let coords: Vec<[f32; 3]> = selected
        .iter()
        .map(|&g| splats.means[g as usize].to_array())
        .collect();
    let tree: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(&coords);
    let two = std::num::NonZeroUsize::new(2).unwrap_or(std::num::NonZeroUsize::MIN);
    let mut d: Vec<f32> = coords
        .iter()
        .map(|c| {
            tree.nearest_n::<SquaredEuclidean>(c, two)
                .iter()
                .map(|nb| nb.distance)
                .fold(0.0f32, f32::max)
                .sqrt()
        })
        .collect();
    d.sort_by(f32::total_cmp);
    d[d.len() / 2]
}

/// The hulls of one view: the footprints of the selected Gaussians that are visible in it
/// (`visible[g]`), one hull per region (`region_of[i]` for `selected[i]`) or one for all.
pub fn view_hulls(
    projected: &Projected,
    visible: &[bool],
    selected: &[u32],
    region_of: &[u32],
    config: &HullConfig,
    width: u32,
    height: u32,
) -> Vec<Hull> {
    let mut points: std::collections::BTreeMap<u32, Vec<Vec2>> = Default::default();
    for (i, &g) in selected.iter().enumerate() {
        let g = g as usize;
        if !visible[g] || projected.radii[g] == 0 {
            continue;
        }
        let region = if config.per_region { region_of[i] } else { 0 };
        footprint_points(
            projected.means2d[g],
            projected.conics[g],
            points.entry(region).or_default(),
        );
    }
    points
        .into_iter()
        .filter_map(|(region, pts)| {
            let polygon = convex_hull(&pts);
            rasterize_hull(
                &polygon,
                config.dilate_px,
                width,
                height,
                config.min_area_px,
            )
            .map(|(x0, y0, mask)| Hull {
                polygon,
                x0,
                y0,
                mask,
                region,
            })
        })
        .collect()
}

/// The union of a view's hulls as a full-image mask.
pub fn union_mask(hulls: &[Hull], width: u32, height: u32) -> Mask {
    let mut full = Mask::empty(width, height);
    for hull in hulls {
        hull.paint(&mut full);
    }
    full
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn hull_of_a_square_with_inner_points_is_its_corners() {
        let pts = [
            Vec2::new(0.0, 0.0),
            Vec2::new(4.0, 0.0),
            Vec2::new(4.0, 4.0),
            Vec2::new(0.0, 4.0),
            Vec2::new(2.0, 2.0),
            Vec2::new(1.0, 3.0),
            Vec2::new(2.0, 0.0),
        ];
        let hull = convex_hull(&pts);
        assert_eq!(hull.len(), 4, "{hull:?}");
        for corner in [
            Vec2::new(0.0, 0.0),
            Vec2::new(4.0, 0.0),
            Vec2::new(4.0, 4.0),
            Vec2::new(0.0, 4.0),
        ] {
            assert!(hull.contains(&corner));
        }
    }

    #[test]
    fn footprints_of_two_round_gaussians_give_the_hand_computed_hull() {
        // Two isotropic Gaussians of σ = 2 px (conic 1/4 on the diagonal, blur ignored) at
        // (10, 10) and (30, 10): their 3σ discs (radius 6) have the stadium hull from x = 4 to
        // 36 and y = 4 to 16. Area of the hull through 12 samples per circle: the rectangle
        // 20 × 12 plus the 12-gon of radius 6 (3 r² = 108): 348 pixels.
        let mut pts = Vec::new();
        for x in [10.0, 30.0] {
            footprint_points(Vec2::new(x, 10.0), Vec3::new(0.25, 0.0, 0.25), &mut pts);
        }
        let hull = convex_hull(&pts);
        let (lo, hi) = hull.iter().fold(
            (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY)),
            |(lo, hi), &v| (lo.min(v), hi.max(v)),
        );
        assert!(
            (lo - Vec2::new(4.0, 4.0)).abs().max_element() < 1e-4,
            "{lo}"
        );
        assert!(
            (hi - Vec2::new(36.0, 16.0)).abs().max_element() < 1e-4,
            "{hi}"
        );
        let (_, _, mask) = rasterize_hull(&hull, 0.0, 64, 32, 1).unwrap();
        // Pixel-centre sampling of a 348 px² polygon: within its perimeter's half-pixel band.
        let area = mask.count() as f32;
        assert!((area - 348.0).abs() < 0.5 * 70.0, "{area}");
        // Dilated by 3 px: the stadium grows to about 20 × 18 + π 9² = 614 pixels.
        let (_, _, dilated) = rasterize_hull(&hull, 3.0, 64, 32, 1).unwrap();
        let grown = dilated.count() as f32;
        assert!((grown - 614.0).abs() < 0.05 * 614.0, "{grown}");
        // Outside the image nothing is kept, and a tiny hull is dropped.
        assert!(rasterize_hull(&hull, 0.0, 64, 32, 10_000).is_none());
    }

    #[test]
    fn regions_split_by_distance() {
        let mut splats = Splats::empty(0, 0);
        for (id, x) in [0.0, 0.1, 0.2, 5.0, 5.1].iter().enumerate() {
            splats.push(
                Vec3::new(*x, 0.0, 0.0),
                Vec3::ZERO,
                glam::Quat::IDENTITY,
                0.0,
                &[0.0; 3],
                &[],
                id as u64,
                0,
            );
        }
        let region = regions(&splats, &[0, 1, 2, 3, 4], 0.15);
        assert_eq!(region, vec![0, 0, 0, 1, 1]);
    }

    #[test]
    fn hulls_from_the_selections_tiles_are_the_whole_renders_hulls() {
        use crate::raster::RenderSettings;
        use crate::raster::weight_lift::WeightLift;
        use crate::scene::{Camera, Intrinsics};
        // A wall of Gaussians at z = 0 and two "cracks" (thin rows of small Gaussians just in
        // front of it, one partly behind a blob), seen from z = 5 at 192×128 (12 × 8 tiles).
        let mut splats = Splats::empty(0, 0);
        let mut rng = fastrand::Rng::with_seed(3);
        let mut push = |splats: &mut Splats, mean: Vec3, scale: f32, opacity: f32| {
            let id = splats.len() as u64;
            let colour = [rng.f32(), rng.f32(), rng.f32()];
            splats.push(
                mean,
                Vec3::splat(scale.ln()),
                glam::Quat::IDENTITY,
                opacity,
                &colour,
                &[],
                id,
                0,
            );
        };
        for i in 0..300 {
            let (x, y) = ((i % 20) as f32 * 0.3 - 3.0, (i / 20) as f32 * 0.3 - 2.1);
            push(&mut splats, Vec3::new(x, y, 0.0), 0.12, 1.0);
        }
        let first_crack = splats.len() as u32;
        for i in 0..30 {
            let t = i as f32 / 29.0;
            push(
                &mut splats,
                Vec3::new(-2.2 + t, -1.0 + 0.5 * t, 0.2),
                0.03,
                2.0,
            );
            push(
                &mut splats,
                Vec3::new(1.0 + 0.8 * t, 0.8 - t, 0.2),
                0.03,
                2.0,
            );
        }
        let selected: Vec<u32> = (first_crack..splats.len() as u32).collect();
        push(&mut splats, Vec3::new(-1.8, -0.8, 1.5), 0.15, 3.0);
        let region_of: Vec<u32> = (0..selected.len() as u32).map(|i| i % 2).collect();
        let k = Intrinsics {
            width: 192,
            height: 128,
            fx: 110.0,
            fy: 110.0,
            cx: 96.0,
            cy: 64.0,
        };
        let camera = Camera::new(k, glam::Quat::IDENTITY, Vec3::new(0.0, 0.0, 5.0));
        let settings = RenderSettings::new(Vec3::ZERO, splats.sh_degree);
        let config = HullConfig::default();
        let draw = |weights: &[f32], lift: &WeightLift| {
            let visible: Vec<bool> = weights.iter().map(|&w| w > 0.1).collect();
            view_hulls(
                lift.projected(),
                &visible,
                &selected,
                &region_of,
                &config,
                k.width,
                k.height,
            )
        };
        let mut whole = WeightLift::new(&splats, 1, settings);
        let weights = whole.view(&camera, |_, _| 1.0).to_vec();
        let plain = draw(&weights, &whole);
        let mut focused = WeightLift::new(&splats, 1, settings);
        let weights = focused.view_of(&camera, &selected, |_, _| 1.0).to_vec();
        let fast = draw(&weights, &focused);
        assert_eq!(plain.len(), 2, "one hull per crack");
        assert!(plain.iter().all(|h| h.area() > 100));
        assert_eq!(fast, plain, "hull masks differ from the whole render's");
    }
}
