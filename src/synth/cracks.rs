//! Cracks as thin branching polylines in a facade's 2D `(u, v)` coordinates, grown by a seeded
//! random walk, and a per-facade spatial grid of their segments so that evaluating a hit point
//! costs a handful of distance tests. No rendering or mask logic beyond coverage and distance.

use glam::Vec2;

/// One polyline with a width (metres) at every vertex; branches are separate cracks.
#[derive(Clone, Debug, PartialEq)]
pub struct Crack {
    pub points: Vec<Vec2>,
    pub widths: Vec<f32>,
    /// 0 for a main crack, 1.. for branches.
    pub generation: u32,
    /// The damage region (`truth/quantities.json` id) the crack belongs to: a main crack, its
    /// branches and its later extensions share one.
    pub region: u32,
}

/// Parameters of one grown crack.
#[derive(Clone, Copy, Debug)]
pub struct CrackSeed {
    pub start: Vec2,
    /// Direction in radians in the (u, v) plane (v up).
    pub angle: f32,
    pub length: f32,
    pub width: f32,
    /// Region id given to the crack and its branches.
    pub region: u32,
}

const STEP: f32 = 0.035;
/// Thinnest crack tip (metres).
const MIN_WIDTH: f32 = 0.006;

/// Grows a crack and its branches into `out` (main crack first, then branches depth first).
pub fn grow(
    rng: &mut fastrand::Rng,
    seed: CrackSeed,
    bounds: (Vec2, Vec2),
    generation: u32,
    out: &mut Vec<Crack>,
) {
    let steps = ((seed.length / STEP).ceil() as usize).max(2);
    let mut theta = seed.angle;
    let mut p = seed.start;
    let mut points = vec![p];
    let mut widths = vec![seed.width];
    let mut branches = Vec::new();
    for i in 1..=steps {
        // Jitter with a pull back to the main direction: cracks wander but keep their course.
        theta += (rng.f32() - 0.5) * 0.55 + (seed.angle - theta) * 0.2;
        p += STEP * Vec2::new(theta.cos(), theta.sin());
        if !(p.x > bounds.0.x && p.x < bounds.1.x && p.y > bounds.0.y && p.y < bounds.1.y) {
            break;
        }
        let f = i as f32 / steps as f32;
        let w = (seed.width * (1.0 - 0.75 * f.powf(0.8))).max(MIN_WIDTH);
        points.push(p);
        widths.push(w);
        if generation < 2 && i > 4 && i + 4 < steps && rng.f32() < 0.035 {
            let side = if rng.bool() { 1.0 } else { -1.0 };
            branches.push(CrackSeed {
                start: p,
                angle: theta + side * (0.35 + 0.5 * rng.f32()),
                length: (steps - i) as f32 * STEP * (0.3 + 0.4 * rng.f32()),
                width: w * 0.6,
                region: seed.region,
            });
        }
    }
    if points.len() >= 2 {
        out.push(Crack {
            points,
            widths,
            generation,
            region: seed.region,
        });
    }
    for b in branches {
        grow(rng, b, bounds, generation + 1, out);
    }
}

#[derive(Clone, Copy, Debug)]
struct Segment {
    a: Vec2,
    b: Vec2,
    half_a: f32,
    half_b: f32,
}

/// What a crack field says at one surface point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CrackHit {
    /// Fraction of the pixel footprint the crack covers (for the photo).
    pub coverage: f32,
    /// Whether the point belongs to the crack mask: inside the crack, or the crack's centre
    /// line passes within half a footprint (thin cracks still get a connected 1-pixel mask).
    pub in_mask: bool,
}

/// All segments of one facade's cracks in a uniform grid (CSR layout).
#[derive(Clone, Debug, Default)]
pub struct CrackField {
    origin: Vec2,
    cell: f32,
    nu: usize,
    nv: usize,
    cell_start: Vec<u32>,
    cell_segments: Vec<u32>,
    segments: Vec<Segment>,
}

const CELL: f32 = 0.25;
/// Segments are binned with this margin, so filters up to twice it see every segment.
const MARGIN: f32 = 0.06;

impl CrackField {
    pub fn new(cracks: &[Crack], u_range: (f32, f32), v_range: (f32, f32)) -> CrackField {
        let origin = Vec2::new(u_range.0 - 1.0, v_range.0 - 1.0);
        let nu = (((u_range.1 - u_range.0) + 2.0) / CELL).ceil() as usize + 1;
        let nv = (((v_range.1 - v_range.0) + 2.0) / CELL).ceil() as usize + 1;
        let mut segments = Vec::new();
        for c in cracks {
            for k in 1..c.points.len() {
                segments.push(Segment {
                    a: c.points[k - 1],
                    b: c.points[k],
                    half_a: 0.5 * c.widths[k - 1],
                    half_b: 0.5 * c.widths[k],
                });
            }
        }
        let mut bins: Vec<Vec<u32>> = vec![Vec::new(); nu * nv];
        for (i, s) in segments.iter().enumerate() {
            let r = s.half_a.max(s.half_b) + MARGIN;
            let lo = (s.a.min(s.b) - Vec2::splat(r) - origin) / CELL;
            let hi = (s.a.max(s.b) + Vec2::splat(r) - origin) / CELL;
            let (u0, v0) = (
                lo.x.floor().max(0.0) as usize,
                lo.y.floor().max(0.0) as usize,
            );
            let (u1, v1) = (
                (hi.x.floor().max(0.0) as usize).min(nu - 1),
                (hi.y.floor().max(0.0) as usize).min(nv - 1),
            );
            for v in v0..=v1 {
                for u in u0..=u1 {
                    bins[v * nu + u].push(i as u32);
                }
            }
        }
        let mut cell_start = Vec::with_capacity(nu * nv + 1);
        let mut cell_segments = Vec::new();
        cell_start.push(0);
        for b in &bins {
            cell_segments.extend_from_slice(b);
            cell_start.push(cell_segments.len() as u32);
        }
        CrackField {
            origin,
            cell: CELL,
            nu,
            nv,
            cell_start,
            cell_segments,
            segments,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.segments.is_empty()
    }

    /// Crack coverage and mask membership at `p` for a pixel footprint `filter` (metres).
    pub fn query(&self, p: Vec2, filter: f32) -> CrackHit {
        let mut hit = CrackHit::default();
        if self.segments.is_empty() {
            return hit;
        }
        let g = (p - self.origin) / self.cell;
        if !(g.x >= 0.0 && g.y >= 0.0) {
            return hit;
        }
        let (cu, cv) = (g.x as usize, g.y as usize);
        if cu >= self.nu || cv >= self.nv {
            return hit;
        }
        let c = cv * self.nu + cu;
        let range = self.cell_start[c] as usize..self.cell_start[c + 1] as usize;
        for &si in &self.cell_segments[range] {
            let s = &self.segments[si as usize];
            let ab = s.b - s.a;
            let t = ((p - s.a).dot(ab) / ab.length_squared().max(1e-12)).clamp(0.0, 1.0);
            let d = (p - (s.a + ab * t)).length();
            let half = s.half_a + (s.half_b - s.half_a) * t;
            hit.coverage = hit
                .coverage
                .max(super::noise::band_coverage(d, half, filter));
            if d < half.max(0.5 * filter) {
                hit.in_mask = true;
            }
        }
        hit
    }
}

/// Survey 2's growth of old cracks: each first-generation crack that `keep` accepts continues,
/// with even odds, from its end in its own direction by `length[0] + length[1] × u` (u uniform
/// in [0, 1)), at least `min_width` wide. Growth of an old crack is not new damage: it keeps the
/// crack's region. Returns the extensions.
pub fn extend_old_cracks(
    rng: &mut fastrand::Rng,
    cracks: &[Crack],
    keep: impl Fn(&Crack) -> bool,
    bounds: (Vec2, Vec2),
    length: [f32; 2],
    min_width: f32,
) -> Vec<Crack> {
    let mut extended = Vec::new();
    for c in cracks.iter().filter(|c| c.generation == 0 && keep(c)) {
        if rng.f32() < 0.5 {
            let n = c.points.len();
            let dir = c.points[n - 1] - c.points[n - 2];
            let seed = CrackSeed {
                start: c.points[n - 1],
                angle: dir.y.atan2(dir.x),
                length: length[0] + length[1] * rng.f32(),
                width: c.widths[n - 1].max(min_width),
                region: c.region,
            };
            grow(rng, seed, bounds, 1, &mut extended);
        }
    }
    extended
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grown_cracks_stay_in_bounds_and_taper() {
        let mut rng = fastrand::Rng::with_seed(3);
        let mut out = Vec::new();
        let bounds = (Vec2::new(0.0, 0.0), Vec2::new(4.0, 3.0));
        let seed = CrackSeed {
            start: Vec2::new(1.0, 1.0),
            angle: 0.8,
            length: 1.5,
            width: 0.04,
            region: 0,
        };
        grow(&mut rng, seed, bounds, 0, &mut out);
        assert!(!out.is_empty());
        for c in &out {
            assert!(
                c.points
                    .iter()
                    .all(|p| p.x > 0.0 && p.y > 0.0 && p.x < 4.0 && p.y < 3.0)
            );
            assert!(c.widths.last().unwrap() <= &c.widths[0]);
        }
    }

    #[test]
    fn field_finds_points_on_the_crack_and_not_beside_it() {
        let crack = Crack {
            points: vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 1.0)],
            widths: vec![0.03, 0.03],
            generation: 0,
            region: 0,
        };
        let field = CrackField::new(&[crack], (0.0, 2.0), (0.0, 2.0));
        assert!(field.query(Vec2::new(0.5, 0.5), 0.01).in_mask);
        assert_eq!(field.query(Vec2::new(0.5, 0.5), 0.01).coverage, 1.0);
        assert!(!field.query(Vec2::new(0.6, 0.5), 0.01).in_mask);
        assert_eq!(field.query(Vec2::new(1.5, 0.2), 0.01).coverage, 0.0);
    }
}
