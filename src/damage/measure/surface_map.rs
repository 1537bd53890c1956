//! The damage labels of one surface plane seen straight on: every Gaussian near the plane
//! splatted orthographically onto it, front to back from the side the cameras saw it from, with
//! the label channels blended as the camera renderer blends them. The map's cell is the ground
//! size of a photo's pixel, and each footprint is widened by the renderer's 0.3 px² screen-space
//! filter at that size: a twin trained from ~1 cm pixels draws thin cracks with Gaussians thinner
//! than the crack, relying on that filter, so a finer map would show them too thin.

use glam::{DVec2, DVec3, Quat, Vec3};

use crate::splats::Splats;
use crate::splats::model::sigmoid;

/// gsplat's screen-space dilation, in pixels² (the renderer's `COV_BLUR`).
const SCREEN_BLUR: f64 = 0.3;
/// Footprints are cut at this many standard deviations.
const FOOTPRINT_SIGMAS: f64 = 3.0;

/// An orthographic frame on a plane: `origin + u * axis_u + v * axis_v`, with `toward_viewer`
/// the normal pointing to the side the surface was photographed from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneFrame {
    pub origin: DVec3,
    pub axis_u: DVec3,
    pub axis_v: DVec3,
    pub toward_viewer: DVec3,
}

impl PlaneFrame {
    /// A frame for the plane `normal · x = offset` facing the viewer side `toward_viewer`
    /// (any normal's sign).
    pub fn new(normal: DVec3, offset: f64, toward_viewer: bool) -> PlaneFrame {
        let n = if toward_viewer { normal } else { -normal };
        let helper = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
        let axis_u = n.cross(helper).normalize();
        let axis_v = n.cross(axis_u);
        PlaneFrame {
            origin: normal * offset,
            axis_u,
            axis_v,
            toward_viewer: n,
        }
    }

    pub fn uv(&self, p: DVec3) -> DVec2 {
        let d = p - self.origin;
        DVec2::new(d.dot(self.axis_u), d.dot(self.axis_v))
    }

    /// Signed distance from the plane toward the viewer.
    pub fn height(&self, p: DVec3) -> f64 {
        (p - self.origin).dot(self.toward_viewer)
    }

    pub fn point(&self, uv: DVec2) -> DVec3 {
        self.origin + self.axis_u * uv.x + self.axis_v * uv.y
    }
}

/// Blended labels on a grid of `cell`-sized squares: `labels[(y * width + x) * channels + k]`,
/// cell (x, y) centred at `lower + (x + ½, y + ½) * cell` in plane coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceMap {
    pub frame: PlaneFrame,
    pub lower: DVec2,
    pub cell: f64,
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub labels: Vec<f32>,
}

impl SurfaceMap {
    pub fn label(&self, x: usize, y: usize, channel: usize) -> f32 {
        self.labels[(y * self.width + x) * self.channels + channel]
    }

    /// Plane coordinates of a cell's centre.
    pub fn cell_uv(&self, x: usize, y: usize) -> DVec2 {
        self.lower + DVec2::new(x as f64 + 0.5, y as f64 + 0.5) * self.cell
    }
}

/// Splats the Gaussians of `splats` within `slab` metres of the plane and inside the
/// rectangle `[lower, upper]` (plus their footprints) onto a map of `cell`-sized squares.
/// Hidden and deleted Gaussians are left out.
pub fn surface_map(
    splats: &Splats,
    frame: PlaneFrame,
    lower: DVec2,
    upper: DVec2,
    cell: f64,
    slab: f64,
) -> SurfaceMap {
    use crate::splats::model::state::{DELETED, HIDDEN};
    let channels = splats.label_channels;
    let width = ((upper.x - lower.x) / cell).ceil().max(1.0) as usize;
    let height = ((upper.y - lower.y) / cell).ceil().max(1.0) as usize;
    let blur = SCREEN_BLUR * cell * cell;

    // Footprints in plane coordinates, nearest the viewer first.
    // (distance from the viewer, Gaussian, centre, conic, reach along u and v)
    let mut footprints: Vec<(f64, usize, DVec2, [f64; 3], DVec2)> = Vec::new();
    for g in 0..splats.len() {
        if splats.meta.state[g] & (HIDDEN | DELETED) != 0 {
            continue;
        }
        let mean = splats.means[g].as_dvec3();
        let h = frame.height(mean);
        if !(h.abs() < slab) {
            continue;
        }
        let uv = frame.uv(mean);
        let cov = plane_covariance(splats.log_scales[g], splats.rotations[g], &frame);
        let (a, b, c) = (cov[0] + blur, cov[1], cov[2] + blur);
        let reach = FOOTPRINT_SIGMAS * a.max(c).sqrt();
        if uv.x + reach < lower.x
            || uv.x - reach > upper.x
            || uv.y + reach < lower.y
            || uv.y - reach > upper.y
        {
            continue;
        }
        let det = a * c - b * b;
        if !(det > 0.0) {
            continue;
        }
        // The inverse covariance (conic), as the renderer evaluates it.
        let reach = FOOTPRINT_SIGMAS * DVec2::new(a.sqrt(), c.sqrt());
        footprints.push((-h, g, uv, [c / det, -b / det, a / det], reach));
    }
    footprints.sort_by(|p, q| p.0.total_cmp(&q.0));

    let mut labels = vec![0.0f32; width * height * channels];
    let mut transmittance = vec![1.0f32; width * height];
    for &(_, g, uv, conic, reach) in &footprints {
        let opacity = sigmoid(splats.raw_opacities[g]) as f64;
        let probabilities: Vec<f32> = splats.labels_of(g).iter().map(|&l| sigmoid(l)).collect();
        let (reach_u, reach_v) = (reach.x, reach.y);
        let x0 = (((uv.x - reach_u - lower.x) / cell).floor().max(0.0)) as usize;
        let y0 = (((uv.y - reach_v - lower.y) / cell).floor().max(0.0)) as usize;
        let x1 = (((uv.x + reach_u - lower.x) / cell).ceil().max(0.0) as usize).min(width);
        let y1 = (((uv.y + reach_v - lower.y) / cell).ceil().max(0.0) as usize).min(height);
        for y in y0..y1 {
            let dy = lower.y + (y as f64 + 0.5) * cell - uv.y;
            for x in x0..x1 {
                let dx = lower.x + (x as f64 + 0.5) * cell - uv.x;
                let power =
                    -0.5 * (conic[0] * dx * dx + 2.0 * conic[1] * dx * dy + conic[2] * dy * dy);
                let alpha = (opacity * power.exp()).min(0.99) as f32;
                if alpha < 1.0 / 255.0 {
                    continue;
                }
                let i = y * width + x;
                let weight = alpha * transmittance[i];
                for (k, p) in probabilities.iter().enumerate() {
                    labels[i * channels + k] += weight * p;
                }
                transmittance[i] *= 1.0 - alpha;
            }
        }
    }
    SurfaceMap {
        frame,
        lower,
        cell,
        width,
        height,
        channels,
        labels,
    }
}

/// A Gaussian's covariance projected onto the plane: (uu, uv, vv).
fn plane_covariance(log_scale: Vec3, rotation: Quat, frame: &PlaneFrame) -> [f64; 3] {
    let r = glam::DMat3::from_quat(rotation.as_dquat().normalize());
    let s = log_scale.as_dvec3().exp();
    let (u, v) = (r.transpose() * frame.axis_u, r.transpose() * frame.axis_v);
    let (su, sv) = (u * s, v * s);
    [su.dot(su), su.dot(sv), sv.dot(sv)]
}
