//! The plain reference of the rasterizer: one Gaussian, then one pixel at a time, with the
//! standard library's `exp`, no SIMD, no segment store and no threads. The fast kernels
//! (`project`, `bin`, `segments`, `forward`, `raster_backward`, `project_backward`) and the GPU
//! stages are tested against it (gsplat's rule: a plain reference beside each fast kernel); it
//! must never be used for speed. The backward lives in `reference_backward.rs`.
//!
//! Stages, each public so that a fast or GPU stage can be compared with its twin alone:
//! [`project`] (3D Gaussians to [`Projected`]), [`blend`] (a [`Projected`] to a
//! [`RenderOutput`]), [`blend_backward`] (pixel gradients to [`ScreenGrads`]) and
//! [`project_backward`] (screen gradients to [`SplatGrads`]); [`render`] and [`backward`] chain
//! them. Equation numbers are those of Kerbl et al., "3D Gaussian Splatting for Real-Time
//! Radiance Field Rendering" (SIGGRAPH 2023); where the paper leaves a detail open (the
//! Jacobian's clamp, the radius, the thresholds) the reference follows gsplat's classic mode,
//! as the fast path does. Every guard is written so that NaN fails it (`!(z > near)`).

use glam::{Mat3, Vec2, Vec3, Vec4};

pub use super::reference_backward::{backward, blend_backward, project_backward};
use super::{
    COV2D_BLUR, FAR_PLANE, Projected, RenderOutput, RenderSettings, TILE_SIZE, TRANSMITTANCE_MIN,
};
use crate::scene::Camera;
use crate::splats::Splats;
use crate::splats::model::sigmoid;
use crate::splats::sh::eval_sh;

/// The pinhole camera as projection uses it: world-to-camera `W, t`, intrinsics, and gsplat's
/// limits on the EWA Jacobian.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pinhole {
    /// `W`: world-to-camera rotation.
    pub world_to_camera: Mat3,
    pub translation: Vec3,
    /// Camera centre in world coordinates (the SH view direction starts here).
    pub position: Vec3,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: u32,
    pub height: u32,
    /// gsplat clamps `x / z` to `[-x_limit.0, x_limit.1]` (and `y / z` likewise) in the
    /// Jacobian: the image's half-widths on each side of the principal point plus 30 % of the
    /// field of view. Far off-screen Gaussians would otherwise get huge, wrong 2D footprints
    /// (the affine approximation of eq. 5 breaks down away from the optical axis).
    pub x_limit: (f32, f32),
    pub y_limit: (f32, f32),
    /// `RenderSettings::near_plane`.
    pub near_plane: f32,
}

impl Pinhole {
    pub fn new(camera: &Camera, settings: &RenderSettings) -> Pinhole {
        let k = &camera.intrinsics;
        let (w, h) = (k.width as f32, k.height as f32);
        let (tan_fov_x, tan_fov_y) = (0.5 * w / k.fx, 0.5 * h / k.fy);
        Pinhole {
            world_to_camera: camera.rotation_matrix(),
            translation: camera.translation,
            position: camera.position(),
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            width: k.width,
            height: k.height,
            x_limit: (
                k.cx / k.fx + 0.3 * tan_fov_x,
                (w - k.cx) / k.fx + 0.3 * tan_fov_x,
            ),
            y_limit: (
                k.cy / k.fy + 0.3 * tan_fov_y,
                (h - k.cy) / k.fy + 0.3 * tan_fov_y,
            ),
            near_plane: settings.near_plane,
        }
    }
}

/// A 3×3 matrix from its rows (glam stores columns).
pub(crate) fn from_rows(rows: [[f32; 3]; 3]) -> Mat3 {
    Mat3::from_cols_array_2d(&rows).transpose()
}

/// Rotation matrix of a unit quaternion `(x, y, z, w)` (glam's order).
pub(crate) fn rotation_matrix(q: Vec4) -> Mat3 {
    let (x, y, z, w) = (q.x, q.y, q.z, q.w);
    from_rows([
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ])
}

/// One Gaussian in camera space: what projection computes and its backward needs again.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CameraSpace {
    /// The mean in camera coordinates, `W μ + t`.
    pub p: Vec3,
    /// The stored quaternion's length and the unit quaternion.
    pub rotation_norm: f32,
    pub unit_rotation: Vec4,
    /// `R` and `S = diag(exp(log_scale))` of eq. 6.
    pub rotation: Mat3,
    pub scale: Vec3,
    /// `Σ_cam = W Σ Wᵀ`.
    pub cov_cam: Mat3,
    /// The two rows of the EWA Jacobian `J` (a 2×3 matrix).
    pub jacobian: [Vec3; 2],
    /// `x / z` and `y / z` as the Jacobian used them (clamped to gsplat's limits), and whether
    /// they lay inside the limits (where they did not, `J` holds the limit, a constant).
    pub clamped_uv: Vec2,
    pub inside_x: bool,
    pub inside_y: bool,
    /// `Σ' = J Σ_cam Jᵀ + 0.3 I` as `(a, b, c)` = `[[a, b], [b, c]]`.
    pub cov2d: Vec3,
}

/// Camera-space quantities of Gaussian `g`, or `None` when it is culled: not in front of the
/// near plane, beyond the far plane, or with a zero (or NaN) rotation.
pub(crate) fn camera_space(splats: &Splats, g: usize, cam: &Pinhole) -> Option<CameraSpace> {
    let w = cam.world_to_camera;
    let p = w * splats.means[g] + cam.translation;
    if !(p.z > cam.near_plane && p.z < FAR_PLANE) {
        return None;
    }
    let q = Vec4::from(splats.rotations[g]);
    let rotation_norm = q.length();
    if !(rotation_norm > 0.0) {
        return None;
    }
    let unit_rotation = q / rotation_norm;
    let rotation = rotation_matrix(unit_rotation);
    let scale = splats.log_scales[g].exp();
    // Eq. 6: Σ = R S Sᵀ Rᵀ, then into camera space: Σ_cam = W Σ Wᵀ.
    let m = rotation * Mat3::from_diagonal(scale);
    let cov_world = m * m.transpose();
    let cov_cam = w * cov_world * w.transpose();
    // The Jacobian of the perspective projection at the mean (Zwicker et al.'s EWA splatting):
    // J = [[fx / z, 0, -fx x / z²], [0, fy / z, -fy y / z²]], with x / z and y / z clamped.
    let (u, v) = (p.x / p.z, p.y / p.z);
    let u_clamped = u.clamp(-cam.x_limit.0, cam.x_limit.1);
    let v_clamped = v.clamp(-cam.y_limit.0, cam.y_limit.1);
    let jacobian = [
        Vec3::new(cam.fx / p.z, 0.0, -cam.fx * u_clamped / p.z),
        Vec3::new(0.0, cam.fy / p.z, -cam.fy * v_clamped / p.z),
    ];
    // Eq. 5: Σ' = J W Σ Wᵀ Jᵀ, plus the 0.3 px² low-pass of the 3DGS code (EWA's screen filter),
    // which keeps every footprint at least about a pixel wide.
    let [j0, j1] = jacobian;
    let cov2d = Vec3::new(
        j0.dot(cov_cam * j0) + COV2D_BLUR,
        j0.dot(cov_cam * j1),
        j1.dot(cov_cam * j1) + COV2D_BLUR,
    );
    Some(CameraSpace {
        p,
        rotation_norm,
        unit_rotation,
        rotation,
        scale,
        cov_cam,
        jacobian,
        clamped_uv: Vec2::new(u_clamped, v_clamped),
        inside_x: -cam.x_limit.0 <= u && u <= cam.x_limit.1,
        inside_y: -cam.y_limit.0 <= v && v <= cam.y_limit.1,
        cov2d,
    })
}

/// Unit view direction from the camera centre to the mean, and the distance (the SH input).
pub(crate) fn view_direction(mean: Vec3, cam: &Pinhole) -> (Vec3, f32) {
    let offset = mean - cam.position;
    let distance = offset.length();
    (offset / distance, distance)
}

/// One projected Gaussian, as [`Projected`] stores it.
struct ProjectedGaussian {
    mean2d: Vec2,
    conic: Vec3,
    depth: f32,
    radius: u32,
    color: Vec3,
    color_pass: u8,
    opacity: f32,
    labels: Vec<f32>,
    extent: Vec2,
}

/// Half-sizes of the box outside which `opacity · exp(-power)` is below the alpha threshold, as
/// the fast path defines [`Projected::extents`] (it bins by them; the reference does not need
/// them). `power <= ln(opacity / threshold)` is an ellipse whose box has half-sizes
/// `sqrt(2 · power_max · Σ'_xx)`, `sqrt(2 · power_max · Σ'_yy)`; the margins are the fast path's.
fn alpha_extent(opacity: f32, cov2d: Vec3, alpha_threshold: f32) -> Vec2 {
    let power_max = if opacity >= alpha_threshold {
        (opacity / alpha_threshold).ln() + 1e-3
    } else {
        -1.0
    };
    let half = |variance: f32| {
        if power_max > 0.0 {
            (2.0 * power_max * variance).sqrt() * 1.001 + 0.01
        } else {
            0.0
        }
    };
    Vec2::new(half(cov2d.x), half(cov2d.z))
}

/// Projects Gaussian `g`, or `None` when it is culled.
fn project_gaussian(
    splats: &Splats,
    g: usize,
    cam: &Pinhole,
    sh_degree: u32,
    alpha_threshold: f32,
) -> Option<ProjectedGaussian> {
    let cs = camera_space(splats, g, cam)?;
    let Vec3 { x: a, y: b, z: c } = cs.cov2d;
    let det = a * c - b * b;
    if !(det > 0.0) {
        return None;
    }
    // The conic is the inverse 2D covariance: the exponent of eq. 4 is ½ dᵀ Σ'⁻¹ d.
    let conic = Vec3::new(c / det, -b / det, a / det);
    // Radius: 3 standard deviations along the larger eigenvalue of Σ', rounded up. gsplat
    // floors the discriminant at 0.01, so a round footprint still gets λ = mid + 0.1.
    let mid = 0.5 * (a + c);
    let lambda_max = mid + (mid * mid - det).max(0.01).sqrt();
    let radius = (3.0 * lambda_max.sqrt()).ceil();
    // Pixel coordinates with pixel centres at +0.5 (the intrinsics' convention).
    let p = cs.p;
    let mean2d = Vec2::new(cam.fx * p.x / p.z + cam.cx, cam.fy * p.y / p.z + cam.cy);
    let (width, height) = (cam.width as f32, cam.height as f32);
    let on_screen = radius > 0.0
        && mean2d.x + radius > 0.0
        && mean2d.x - radius < width
        && mean2d.y + radius > 0.0
        && mean2d.y - radius < height;
    if !on_screen {
        return None;
    }
    let opacity = sigmoid(splats.raw_opacities[g]);
    // Colour: the SH sum in the direction the camera sees the mean from, shifted by 0.5 and
    // clamped at 0 (3DGS's `max(SH(dir) + 0.5, 0)`).
    let k = splats.sh_coeffs() * 3;
    let (dir, _) = view_direction(splats.means[g], cam);
    let sh_sum = eval_sh(sh_degree, &splats.sh[g * k..(g + 1) * k], dir);
    let shifted = sh_sum + Vec3::splat(0.5);
    let l = splats.label_channels;
    let raw_labels = &splats.raw_labels[g * l..(g + 1) * l];
    let extent = alpha_extent(opacity, cs.cov2d, alpha_threshold);
    // Anything non-finite (NaN or infinite parameters) is culled rather than blended; the SH
    // sum is tested before the clamp, which would turn -inf into a finite 0.
    let finite = mean2d.is_finite()
        && conic.is_finite()
        && sh_sum.is_finite()
        && opacity.is_finite()
        && raw_labels.iter().all(|v| v.is_finite())
        && !extent.is_nan();
    if !finite {
        return None;
    }
    Some(ProjectedGaussian {
        mean2d,
        conic,
        depth: p.z,
        radius: radius as u32,
        color: shifted.max(Vec3::ZERO),
        color_pass: (shifted.x >= 0.0) as u8
            | ((shifted.y >= 0.0) as u8) << 1
            | ((shifted.z >= 0.0) as u8) << 2,
        opacity,
        labels: raw_labels.iter().map(|&v| sigmoid(v)).collect(),
        extent,
    })
}

/// Projects every Gaussian of `splats` (3DGS §4, gsplat's projection in classic mode): a culled
/// Gaussian has radius 0 and every other field zero, as in the fast path.
pub fn project(splats: &Splats, camera: &Camera, settings: &RenderSettings) -> Projected {
    let n = splats.len();
    let l = splats.label_channels;
    let cam = Pinhole::new(camera, settings);
    let sh_degree = settings.sh_degree.min(splats.sh_degree);
    let mut out = Projected {
        means2d: vec![Vec2::ZERO; n],
        conics: vec![Vec3::ZERO; n],
        depths: vec![0.0; n],
        radii: vec![0; n],
        colors: vec![Vec3::ZERO; n],
        color_pass: vec![0; n],
        opacities: vec![0.0; n],
        labels: vec![0.0; n * l],
        extents: vec![Vec2::ZERO; n],
    };
    for g in 0..n {
        let Some(p) = project_gaussian(splats, g, &cam, sh_degree, settings.alpha_threshold) else {
            continue;
        };
        out.means2d[g] = p.mean2d;
        out.conics[g] = p.conic;
        out.depths[g] = p.depth;
        out.radii[g] = p.radius;
        out.colors[g] = p.color;
        out.color_pass[g] = p.color_pass;
        out.opacities[g] = p.opacity;
        out.labels[g * l..(g + 1) * l].copy_from_slice(&p.labels);
        out.extents[g] = p.extent;
    }
    out
}

/// gsplat's tile rectangle of a projected Gaussian: tiles `[x0, x1) × [y0, y1)` (as
/// `[x0, y0, x1, y1]`) that the square of half-size `radius` around the mean touches, clipped
/// to a `tiles_x × tiles_y` grid; empty for a culled Gaussian.
pub fn radius_tile_rect(mean2d: Vec2, radius: u32, tiles_x: u32, tiles_y: u32) -> [u32; 4] {
    if radius == 0 {
        return [0; 4];
    }
    let (r, ts) = (radius as f32, TILE_SIZE as f32);
    let clamp = |v: f32, hi: u32| v.max(0.0).min(hi as f32) as u32;
    [
        clamp(((mean2d.x - r) / ts).floor(), tiles_x),
        clamp(((mean2d.y - r) / ts).floor(), tiles_y),
        clamp(((mean2d.x + r) / ts).ceil(), tiles_x),
        clamp(((mean2d.y + r) / ts).ceil(), tiles_y),
    ]
}

/// Per 16×16 tile of a `width × height` image, the Gaussians whose radius rectangle
/// ([`radius_tile_rect`]) covers it, front to back: by depth, ties broken by index (the fast
/// path's key). Only these can blend into the tile's pixels, in gsplat and in the fast path
/// alike, even where a Gaussian's alpha would pass the threshold just outside its rectangle.
///
/// The fast path bins less: it also drops the tiles (and, per 8-pixel row piece, the pixels)
/// where `opacity · exp(-power)` cannot reach the threshold. Those drops must change no pixel;
/// the reference leaves them out, so comparing the two tests that claim.
#[derive(Clone, Debug, Default)]
pub struct TileLists {
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// Indexed by `ty * tiles_x + tx`.
    pub lists: Vec<Vec<usize>>,
}

impl TileLists {
    pub fn new(projected: &Projected, width: u32, height: u32) -> TileLists {
        let (tiles_x, tiles_y) = super::tile_grid(width, height);
        let mut front_to_back: Vec<usize> = (0..projected.radii.len())
            .filter(|&g| projected.radii[g] > 0)
            .collect();
        front_to_back.sort_by(|&i, &j| {
            projected.depths[i]
                .total_cmp(&projected.depths[j])
                .then(i.cmp(&j))
        });
        let mut lists = vec![Vec::new(); (tiles_x * tiles_y) as usize];
        for g in front_to_back {
            let [x0, y0, x1, y1] =
                radius_tile_rect(projected.means2d[g], projected.radii[g], tiles_x, tiles_y);
            for ty in y0..y1 {
                for tx in x0..x1 {
                    lists[(ty * tiles_x + tx) as usize].push(g);
                }
            }
        }
        TileLists {
            tiles_x,
            tiles_y,
            lists,
        }
    }

    /// The Gaussians that can blend into pixel `(x, y)`, front to back.
    pub fn at_pixel(&self, x: u32, y: u32) -> &[usize] {
        let tile = (y / TILE_SIZE) * self.tiles_x + x / TILE_SIZE;
        &self.lists[tile as usize]
    }
}

/// One Gaussian blended into one pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blended {
    pub gaussian: usize,
    /// `d = mean2d - pixel centre` (gsplat's sign).
    pub d: Vec2,
    /// `exp(-power)`, the Gaussian's falloff of eq. 4 at the pixel centre.
    pub falloff: f32,
    /// `opacity · exp(-power)` before the clamp, and `α = min(alpha_max, that)`.
    pub raw_alpha: f32,
    pub alpha: f32,
    /// Transmittance in front of the Gaussian, `T_i = Π_{j<i} (1 - α_j)`.
    pub transmittance: f32,
}

/// Everything blended into one pixel, front to back, and the transmittance left behind it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PixelBlend {
    pub blended: Vec<Blended>,
    pub final_transmittance: f32,
    /// Whether the loop stopped at a Gaussian that would have taken the transmittance to
    /// `1e-4` or below (rather than running out of Gaussians).
    pub stopped: bool,
}

/// The Gaussian's power at `d = mean2d - pixel centre`: the exponent of eq. 4,
/// `½ dᵀ Σ'⁻¹ d` with the conic `(a, b, c)`.
pub fn power(conic: Vec3, d: Vec2) -> f32 {
    0.5 * (conic.x * d.x * d.x + conic.z * d.y * d.y) + conic.y * d.x * d.y
}

/// gsplat's per-pixel loop (`rasterize_to_pixels_fwd`) at pixel `(x, y)`: eq. 3 front to back
/// over the Gaussians of its tile, skipping a Gaussian where its power is negative or its alpha
/// is below the threshold, and stopping before the Gaussian that would take the transmittance
/// to `1e-4` or below (that one is not blended).
pub fn blend_pixel(
    projected: &Projected,
    tiles: &TileLists,
    x: u32,
    y: u32,
    settings: &RenderSettings,
) -> PixelBlend {
    let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
    let mut blended = Vec::new();
    let mut t = 1.0f32;
    let mut stopped = false;
    for &g in tiles.at_pixel(x, y) {
        let d = projected.means2d[g] - centre;
        let sigma = power(projected.conics[g], d);
        let falloff = (-sigma).exp();
        let raw_alpha = projected.opacities[g] * falloff;
        let alpha = raw_alpha.min(settings.alpha_max);
        // gsplat: `if (sigma < 0.f || alpha < 1.f / 255.f) continue;` (written to fail on NaN).
        if !(sigma >= 0.0 && alpha >= settings.alpha_threshold) {
            continue;
        }
        let next_t = t * (1.0 - alpha);
        // gsplat: `if (next_T <= 1e-4f) { done = true; break; }`: the pixel is finished and
        // this Gaussian is not blended.
        if next_t <= TRANSMITTANCE_MIN {
            stopped = true;
            break;
        }
        blended.push(Blended {
            gaussian: g,
            d,
            falloff,
            raw_alpha,
            alpha,
            transmittance: t,
        });
        t = next_t;
    }
    PixelBlend {
        blended,
        final_transmittance: t,
        stopped,
    }
}

/// Blends a projected frame into a `width × height` image (eq. 3 per pixel, [`blend_pixel`]):
/// colour `Σ c_i α_i T_i + T_final · background`, alpha `1 - T_final`, depth `Σ z_i α_i T_i`
/// and label channels `Σ p_ik α_i T_i`, the layouts of [`RenderOutput`].
pub fn blend(
    projected: &Projected,
    label_channels: usize,
    width: u32,
    height: u32,
    settings: &RenderSettings,
) -> RenderOutput {
    let l = label_channels;
    let pixels = (width * height) as usize;
    let mut out = RenderOutput {
        width,
        height,
        label_channels: l,
        color: vec![0.0; pixels * 3],
        alpha: vec![0.0; pixels],
        depth: vec![0.0; pixels],
        labels: vec![0.0; pixels * l],
    };
    let tiles = TileLists::new(projected, width, height);
    for y in 0..height {
        for x in 0..width {
            let pixel = (y * width + x) as usize;
            let blend = blend_pixel(projected, &tiles, x, y, settings);
            let mut color = Vec3::ZERO;
            let mut depth = 0.0;
            let labels = &mut out.labels[pixel * l..(pixel + 1) * l];
            for b in &blend.blended {
                let weight = b.alpha * b.transmittance;
                color += weight * projected.colors[b.gaussian];
                depth += weight * projected.depths[b.gaussian];
                let probabilities = &projected.labels[b.gaussian * l..(b.gaussian + 1) * l];
                for (label, p) in labels.iter_mut().zip(probabilities) {
                    *label += weight * p;
                }
            }
            let t = blend.final_transmittance;
            color += t * settings.background;
            out.color[pixel * 3..pixel * 3 + 3].copy_from_slice(&color.to_array());
            out.alpha[pixel] = 1.0 - t;
            out.depth[pixel] = depth;
        }
    }
    out
}

/// Projects and blends one frame; the [`Projected`] is what the backward starts from.
pub fn render(
    splats: &Splats,
    camera: &Camera,
    settings: &RenderSettings,
) -> (RenderOutput, Projected) {
    let projected = project(splats, camera, settings);
    let k = &camera.intrinsics;
    let out = blend(
        &projected,
        splats.label_channels,
        k.width,
        k.height,
        settings,
    );
    (out, projected)
}
