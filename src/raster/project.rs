//! Projection stage: each 3D Gaussian to a 2D mean, conic, depth, radius, colour and opacity
//! (gsplat's `fully_fused_projection`, classic mode, with the EWA Jacobian and 0.3 px² blur).
//! Per Gaussian and independent, parallel over chunks; it must not touch tiles or pixels.

use glam::{Mat3, Quat, Vec2, Vec3};
use rayon::prelude::*;

use super::{COV2D_BLUR, CameraFrame, FAR_PLANE, NEAR_PLANE, Projected, RenderSettings};
use crate::splats::Splats;
use crate::splats::model::sigmoid;
use crate::splats::sh::eval_sh;

/// Gaussians per parallel work item.
const CHUNK: usize = 1024;

/// Rotation matrix of a unit quaternion (glam order x, y, z, w), written out so that its
/// derivative in `project_backward` is exactly the transpose of this code.
#[inline]
pub(crate) fn rotation_matrix(q: Quat) -> Mat3 {
    let (x, y, z, w) = (q.x, q.y, q.z, q.w);
    Mat3::from_cols(
        Vec3::new(
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y + w * z),
            2.0 * (x * z - w * y),
        ),
        Vec3::new(
            2.0 * (x * y - w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z + w * x),
        ),
        Vec3::new(
            2.0 * (x * z + w * y),
            2.0 * (y * z - w * x),
            1.0 - 2.0 * (x * x + y * y),
        ),
    )
}

/// The two rows of the EWA Jacobian at camera-space `p` (x / z and y / z clamped like gsplat).
#[inline]
pub(crate) fn ewa_jacobian(p: Vec3, frame: &CameraFrame) -> (Vec3, Vec3) {
    let rz = 1.0 / p.z;
    let rz2 = rz * rz;
    let tx = p.z * (p.x * rz).max(-frame.lim_x_neg).min(frame.lim_x_pos);
    let ty = p.z * (p.y * rz).max(-frame.lim_y_neg).min(frame.lim_y_pos);
    (
        Vec3::new(frame.fx * rz, 0.0, -frame.fx * tx * rz2),
        Vec3::new(0.0, frame.fy * rz, -frame.fy * ty * rz2),
    )
}

/// Everything about one Gaussian in camera space that both directions need.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CameraSpace {
    pub p_cam: Vec3,
    /// The rotation's length, the unit quaternion and its matrix, and `exp(log_scale)`: the
    /// backward reuses them rather than computing them again.
    pub norm: f32,
    pub q: Quat,
    pub rot: Mat3,
    pub scale: Vec3,
    /// `W · R · S`: the camera-space covariance is `ws · wsᵀ`.
    pub ws: Mat3,
    pub j0: Vec3,
    pub j1: Vec3,
    /// `Σ_cam · j0`, `Σ_cam · j1`.
    pub t0: Vec3,
    pub t1: Vec3,
    /// Blurred 2D covariance `[[a, b], [b, c]]`.
    pub cov2d: Vec3,
}

/// Camera-space quantities of one Gaussian, or `None` when it is culled by the near/far planes
/// or a degenerate covariance. `if !(x > y)` guards here and below cull NaN too.
#[inline]
pub(crate) fn camera_space(
    mean: Vec3,
    log_scale: Vec3,
    rotation: Quat,
    frame: &CameraFrame,
) -> Option<CameraSpace> {
    let p_cam = frame.world_to_camera * mean + frame.translation;
    if !(p_cam.z > NEAR_PLANE) || !(p_cam.z < FAR_PLANE) {
        return None;
    }
    let norm2 = rotation.length_squared();
    if !(norm2 > 0.0) {
        return None;
    }
    let norm = norm2.sqrt();
    let q = rotation * (1.0 / norm);
    let r = rotation_matrix(q);
    let s = Vec3::new(log_scale.x.exp(), log_scale.y.exp(), log_scale.z.exp());
    let m = Mat3::from_cols(r.x_axis * s.x, r.y_axis * s.y, r.z_axis * s.z);
    let ws = frame.world_to_camera * m;
    let cov_cam = ws * ws.transpose();
    let (j0, j1) = ewa_jacobian(p_cam, frame);
    let t0 = cov_cam * j0;
    let t1 = cov_cam * j1;
    let cov2d = Vec3::new(j0.dot(t0) + COV2D_BLUR, j0.dot(t1), j1.dot(t1) + COV2D_BLUR);
    Some(CameraSpace {
        p_cam,
        norm,
        q,
        rot: r,
        scale: s,
        ws,
        j0,
        j1,
        t0,
        t1,
        cov2d,
    })
}

/// One projected Gaussian (written into the SoA [`Projected`] by the caller).
#[derive(Clone, Copy, Debug, Default)]
struct ProjectedOne {
    mean2d: Vec2,
    conic: Vec3,
    depth: f32,
    radius: u32,
    color: Vec3,
    opacity: f32,
    extent: Vec2,
}

#[inline]
fn project_one(
    splats: &Splats,
    g: usize,
    frame: &CameraFrame,
    sh_degree: u32,
    alpha_threshold: f32,
) -> Option<ProjectedOne> {
    let cs = camera_space(
        splats.means[g],
        splats.log_scales[g],
        splats.rotations[g],
        frame,
    )?;
    let (a, b, c) = (cs.cov2d.x, cs.cov2d.y, cs.cov2d.z);
    let det = a * c - b * b;
    if !(det > 0.0) {
        return None;
    }
    let inv_det = 1.0 / det;
    let conic = Vec3::new(c * inv_det, -b * inv_det, a * inv_det);
    // 3 sigma of the larger eigenvalue; the 0.01 floor is gsplat's.
    let mid = 0.5 * (a + c);
    let lambda = mid + (mid * mid - det).max(0.01).sqrt();
    let radius = (3.0 * lambda.sqrt()).ceil();
    let rz = 1.0 / cs.p_cam.z;
    let mean2d = Vec2::new(
        frame.fx * cs.p_cam.x * rz + frame.cx,
        frame.fy * cs.p_cam.y * rz + frame.cy,
    );
    let (w, h) = (frame.width as f32, frame.height as f32);
    if !(radius > 0.0)
        || !(mean2d.x + radius > 0.0)
        || !(mean2d.x - radius < w)
        || !(mean2d.y + radius > 0.0)
        || !(mean2d.y - radius < h)
    {
        return None;
    }
    let opacity = sigmoid(splats.raw_opacities[g]);
    // opacity · exp(-power) >= 1/255  <=>  power <= ln(255 · opacity); the box of that ellipse
    // has half-sizes sqrt(2 · power_max · Σ_xx), sqrt(2 · power_max · Σ_yy). Margins absorb
    // rounding (the blend loop decides per pixel anyway; the box only limits where it looks).
    let power_max = if opacity >= alpha_threshold {
        (opacity / alpha_threshold).ln() + 1e-3
    } else {
        -1.0
    };
    let extent = if power_max > 0.0 {
        Vec2::new(
            (2.0 * power_max * a).sqrt() * 1.001 + 0.01,
            (2.0 * power_max * c).sqrt() * 1.001 + 0.01,
        )
    } else {
        Vec2::ZERO
    };
    let dir = (splats.means[g] - frame.position).normalize();
    let k = splats.sh_coeffs() * 3;
    let raw = eval_sh(sh_degree, &splats.sh[g * k..(g + 1) * k], dir);
    let color = (raw + Vec3::splat(0.5)).max(Vec3::ZERO);
    let l = splats.label_channels;
    let label_sum: f32 = splats.raw_labels[g * l..(g + 1) * l].iter().sum();
    // Anything non-finite (NaN/Inf parameters) is culled here rather than blended. The SH sum
    // is tested before the clamp: `max(-inf, 0)` would hide an infinite coefficient (the GPU
    // projection tests the same sum).
    let check = conic.x + conic.y + conic.z + mean2d.x + mean2d.y + raw.x + raw.y + raw.z;
    if !(check + opacity + label_sum).is_finite() || extent.is_nan() {
        return None;
    }
    Some(ProjectedOne {
        mean2d,
        conic,
        depth: cs.p_cam.z,
        radius: radius as u32,
        color,
        opacity,
        extent,
    })
}

fn resize<T: Copy + Default>(v: &mut Vec<T>, n: usize) {
    v.clear();
    v.resize(n, T::default());
}

/// Projects every Gaussian of `splats` into `out` (resized, fully overwritten).
pub(crate) fn project(
    splats: &Splats,
    frame: &CameraFrame,
    settings: &RenderSettings,
    out: &mut Projected,
) {
    let n = splats.len();
    let l = splats.label_channels;
    resize(&mut out.means2d, n);
    resize(&mut out.conics, n);
    resize(&mut out.depths, n);
    resize(&mut out.radii, n);
    resize(&mut out.colors, n);
    resize(&mut out.opacities, n);
    resize(&mut out.extents, n);
    resize(&mut out.labels, n * l);
    let sh_degree = settings.sh_degree.min(splats.sh_degree);
    (
        out.means2d.par_chunks_mut(CHUNK),
        out.conics.par_chunks_mut(CHUNK),
        out.depths.par_chunks_mut(CHUNK),
        out.radii.par_chunks_mut(CHUNK),
        out.colors.par_chunks_mut(CHUNK),
        out.opacities.par_chunks_mut(CHUNK),
        out.extents.par_chunks_mut(CHUNK),
    )
        .into_par_iter()
        .enumerate()
        .for_each(
            |(chunk, (means2d, conics, depths, radii, colors, opacities, extents))| {
                for i in 0..means2d.len() {
                    let g = chunk * CHUNK + i;
                    let threshold = settings.alpha_threshold;
                    if let Some(p) = project_one(splats, g, frame, sh_degree, threshold) {
                        means2d[i] = p.mean2d;
                        conics[i] = p.conic;
                        depths[i] = p.depth;
                        radii[i] = p.radius;
                        colors[i] = p.color;
                        opacities[i] = p.opacity;
                        extents[i] = p.extent;
                    }
                }
            },
        );
    if l > 0 {
        let radii = &out.radii;
        out.labels
            .par_chunks_mut(CHUNK * l)
            .enumerate()
            .for_each(|(chunk, labels)| {
                let first = chunk * CHUNK;
                for (i, label) in labels.iter_mut().enumerate() {
                    let g = first + i / l;
                    if radii[g] > 0 {
                        *label = sigmoid(splats.raw_labels[first * l + i]);
                    }
                }
            });
    }
}
