//! Projection stage: each 3D Gaussian to a 2D mean, conic, depth, radius, colour and opacity
//! (gsplat's `fully_fused_projection`, classic mode, with the EWA Jacobian and 0.3 px² blur).
//! Per Gaussian and independent, parallel over chunks; it must not touch tiles or pixels.
//!
//! Eight Gaussians at a time in [`F8`] lanes: the geometry is branch-free and culls through a
//! mask (`x > y` compares fail on NaN, so NaN is culled too), so it vectorises; the SH colour
//! runs per Gaussian after it. Matrices are `[row][col]` arrays of lanes.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::lanes::{F8, LANES, M8, build3, build3x3, group_of};
use super::{COV2D_BLUR, CameraFrame, FAR_PLANE, Projected, RenderSettings};
use crate::scene::Camera;
use crate::simd::simd_dispatch;
use crate::splats::Splats;
use crate::splats::model::sigmoid;
use crate::splats::sh::eval_sh;

/// Gaussians per parallel work item (a multiple of [`LANES`]).
const CHUNK: usize = 1024;

/// A 3×3 matrix of lanes, `[row][col]`.
pub(crate) type M3 = [[F8; 3]; 3];

/// `world_to_camera` as `[row][col]` scalars.
#[inline(always)]
pub(crate) fn world_to_camera_rows(frame: &CameraFrame) -> [[f32; 3]; 3] {
    let w = frame.world_to_camera;
    let mut out = [[0.0; 3]; 3];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = w.col(c)[r];
        }
    }
    out
}

/// `a · b` over three lanes, in glam's order.
#[inline(always)]
pub(crate) fn dot3(a: &[F8; 3], b: &[F8; 3]) -> F8 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Rotation matrix of unit quaternions `(x, y, z, w)`, written out so that its derivative in
/// `project_backward` is exactly the transpose of this code.
#[inline(always)]
pub(crate) fn rotation_matrix(q: &[F8; 4]) -> M3 {
    let [x, y, z, w] = *q;
    [
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
    ]
}

/// The parameters of eight Gaussians, gathered into lanes.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct GaussianLanes {
    pub mean: [F8; 3],
    pub log_scale: [F8; 3],
    /// Un-normalised quaternion `(x, y, z, w)`.
    pub rotation: [F8; 4],
}

impl GaussianLanes {
    /// Gaussians `start..start + live` of `splats` (see [`group_of`]).
    #[inline(always)]
    pub fn gather(splats: &Splats, start: usize, live: usize) -> GaussianLanes {
        let means = group_of(&splats.means, start, live);
        let log_scales = group_of(&splats.log_scales, start, live);
        let rotations = group_of(&splats.rotations, start, live);
        GaussianLanes {
            mean: build3(|a| F8::from_fn(|l| means[l][a])),
            log_scale: build3(|a| F8::from_fn(|l| log_scales[l][a])),
            rotation: [
                F8::from_fn(|l| rotations[l].x),
                F8::from_fn(|l| rotations[l].y),
                F8::from_fn(|l| rotations[l].z),
                F8::from_fn(|l| rotations[l].w),
            ],
        }
    }
}

/// Everything about eight Gaussians in camera space that both directions need.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CameraSpace {
    /// In front of the near plane, before the far plane, and a non-zero rotation: in a lane
    /// where this is false the other fields may hold anything (NaN included).
    pub valid: M8,
    pub p_cam: [F8; 3],
    /// The rotation's length, the unit quaternion and its matrix, and `exp(log_scale)`: the
    /// backward reuses them rather than computing them again.
    pub norm: F8,
    pub q: [F8; 4],
    pub rot: M3,
    pub scale: [F8; 3],
    /// `W · R · S`: the camera-space covariance is `ws · wsᵀ`.
    pub ws: M3,
    /// The two rows of the EWA Jacobian (x / z and y / z clamped like gsplat).
    pub j0: [F8; 3],
    pub j1: [F8; 3],
    /// `Σ_cam · j0`, `Σ_cam · j1`.
    pub t0: [F8; 3],
    pub t1: [F8; 3],
    /// Blurred 2D covariance `[[a, b], [b, c]]`.
    pub cov2d: [F8; 3],
}

/// Camera-space quantities of eight Gaussians. The operations and their order are those of
/// the scalar glam code this replaced (zero Jacobian entries included), so the bits match it.
#[inline(always)]
pub(crate) fn camera_space(x: &GaussianLanes, frame: &CameraFrame) -> CameraSpace {
    let w = world_to_camera_rows(frame);
    let t = frame.translation;
    let mean = &x.mean;
    let p: [F8; 3] = build3(|r| w[r][0] * mean[0] + w[r][1] * mean[1] + w[r][2] * mean[2] + t[r]);
    let [qx, qy, qz, qw] = x.rotation;
    let norm2 = qx * qx + qy * qy + qz * qz + qw * qw;
    let valid = p[2].gt(F8::splat(frame.near_plane))
        & p[2].lt(F8::splat(FAR_PLANE))
        & norm2.gt(F8::splat(0.0));
    let norm = norm2.sqrt();
    let inv_norm = 1.0 / norm;
    let q = [qx * inv_norm, qy * inv_norm, qz * inv_norm, qw * inv_norm];
    let rot = rotation_matrix(&q);
    // Written out: a closure this large is not always inlined into the AVX-compiled caller.
    let scale = [
        x.log_scale[0].exp(),
        x.log_scale[1].exp(),
        x.log_scale[2].exp(),
    ];
    let m: M3 = build3x3(|r, c| rot[r][c] * scale[c]);
    let ws: M3 = build3x3(|r, c| w[r][0] * m[0][c] + w[r][1] * m[1][c] + w[r][2] * m[2][c]);
    let cov: M3 = build3x3(|r, c| dot3(&ws[r], &ws[c]));
    let rz = 1.0 / p[2];
    let rz2 = rz * rz;
    let tx = p[2] * (p[0] * rz).clamp(-frame.lim_x_neg, frame.lim_x_pos);
    let ty = p[2] * (p[1] * rz).clamp(-frame.lim_y_neg, frame.lim_y_pos);
    let zero = F8::splat(0.0);
    let j0 = [frame.fx * rz, zero, -frame.fx * tx * rz2];
    let j1 = [zero, frame.fy * rz, -frame.fy * ty * rz2];
    let t0: [F8; 3] = build3(|r| dot3(&cov[r], &j0));
    let t1: [F8; 3] = build3(|r| dot3(&cov[r], &j1));
    let cov2d = [
        dot3(&j0, &t0) + COV2D_BLUR,
        dot3(&j0, &t1),
        dot3(&j1, &t1) + COV2D_BLUR,
    ];
    CameraSpace {
        valid,
        p_cam: p,
        norm,
        q,
        rot,
        scale,
        ws,
        j0,
        j1,
        t0,
        t1,
        cov2d,
    }
}

/// Eight projected Gaussians but their colour.
#[derive(Clone, Copy, Debug)]
struct ProjectedLanes {
    /// Not culled by the geometry (the caller still checks the colour and labels).
    ok: M8,
    mean2d: [F8; 2],
    conic: [F8; 3],
    depth: F8,
    radius: F8,
    opacity: F8,
    extent: [F8; 2],
    /// Sum of the conic, the 2D mean and the opacity, tested for finiteness with the colour.
    check: F8,
    /// Unit view direction for the SH.
    dir: [F8; 3],
}

/// The geometric part of the projection of eight Gaussians.
#[inline(always)]
fn project_geometry(
    x: &GaussianLanes,
    raw_opacity: F8,
    frame: &CameraFrame,
    alpha_threshold: f32,
) -> ProjectedLanes {
    let cs = camera_space(x, frame);
    let [a, b, c] = cs.cov2d;
    let det = a * c - b * b;
    let inv_det = 1.0 / det;
    let conic = [c * inv_det, -b * inv_det, a * inv_det];
    // 3 sigma of the larger eigenvalue; the 0.01 floor is gsplat's.
    let mid = 0.5 * (a + c);
    let lambda = mid + (mid * mid - det).max(F8::splat(0.01)).sqrt();
    let radius = (3.0 * lambda.sqrt()).ceil();
    let p = cs.p_cam;
    let rz = 1.0 / p[2];
    let mean2d = [
        frame.fx * p[0] * rz + frame.cx,
        frame.fy * p[1] * rz + frame.cy,
    ];
    let (w, h) = (
        F8::splat(frame.width as f32),
        F8::splat(frame.height as f32),
    );
    let zero = F8::splat(0.0);
    let on_screen = radius.gt(zero)
        & (mean2d[0] + radius).gt(zero)
        & (mean2d[0] - radius).lt(w)
        & (mean2d[1] + radius).gt(zero)
        & (mean2d[1] - radius).lt(h);
    let opacity = raw_opacity.sigmoid();
    // opacity · exp(-power) >= 1/255  <=>  power <= ln(255 · opacity); the box of that ellipse
    // has half-sizes sqrt(2 · power_max · Σ_xx), sqrt(2 · power_max · Σ_yy). Margins absorb
    // rounding (the blend loop decides per pixel anyway; the box only limits where it looks).
    let threshold = F8::splat(alpha_threshold);
    let ln_ratio = (opacity / alpha_threshold).ln() + 1e-3;
    let power_max = F8::select(opacity.ge(threshold), ln_ratio, F8::splat(-1.0));
    let has_box = power_max.gt(zero);
    let half = |sigma2: F8| {
        F8::select(
            has_box,
            (2.0 * power_max * sigma2).sqrt() * 1.001 + 0.01,
            zero,
        )
    };
    let extent = [half(a), half(c)];
    let offset: [F8; 3] = build3(|i| x.mean[i] - frame.position[i]);
    let inv_len = 1.0 / dot3(&offset, &offset).sqrt();
    let dir = build3(|i| offset[i] * inv_len);
    let check = conic[0] + conic[1] + conic[2] + mean2d[0] + mean2d[1];
    let ok = cs.valid & det.gt(zero) & on_screen & !extent[0].is_nan() & !extent[1].is_nan();
    ProjectedLanes {
        ok,
        mean2d,
        conic,
        depth: p[2],
        radius,
        opacity,
        extent,
        check,
        dir,
    }
}

/// Each Gaussian's camera-space depth from `camera` as the projection computes it (the
/// operations of `camera_space`, in its order), so the bits are those the near plane culls on:
/// a cull decided on these depths (`timeline::near_floaters::near_floaters`) and one by
/// `RenderSettings::near_plane` agree exactly.
pub fn camera_depths(splats: &Splats, camera: &Camera) -> Vec<f32> {
    let frame = CameraFrame::new(camera, &RenderSettings::default());
    let w = world_to_camera_rows(&frame)[2];
    let t = frame.translation[2];
    splats
        .means
        .iter()
        .map(|m| w[0] * m.x + w[1] * m.y + w[2] * m.z + t)
        .collect()
}

/// The output slices of one chunk.
struct ChunkOut<'a> {
    means2d: &'a mut [Vec2],
    conics: &'a mut [Vec3],
    depths: &'a mut [f32],
    radii: &'a mut [u32],
    colors: &'a mut [Vec3],
    color_pass: &'a mut [u8],
    opacities: &'a mut [f32],
    extents: &'a mut [Vec2],
}

/// Projects Gaussians `first..first + out.means2d.len()`, eight at a time. The last group
/// repeats its last Gaussian in the missing lanes and drops their results, so every
/// Gaussian's bits are independent of where the chunks and groups fall.
#[inline(always)]
fn project_chunk_impl(
    splats: &Splats,
    first: usize,
    frame: &CameraFrame,
    sh_degree: u32,
    alpha_threshold: f32,
    out: &mut ChunkOut<'_>,
) {
    let count = out.means2d.len();
    let k = splats.sh_coeffs() * 3;
    let l = splats.label_channels;
    for group in (0..count).step_by(LANES) {
        let live = LANES.min(count - group);
        let x = GaussianLanes::gather(splats, first + group, live);
        let raw_opacity = F8(group_of(&splats.raw_opacities, first + group, live));
        let p = project_geometry(&x, raw_opacity, frame, alpha_threshold);
        for i in 0..live {
            if !p.ok.0[i] {
                continue;
            }
            let g = first + group + i;
            let dir = Vec3::new(p.dir[0].0[i], p.dir[1].0[i], p.dir[2].0[i]);
            let raw = eval_sh(sh_degree, &splats.sh[g * k..(g + 1) * k], dir);
            let label_sum: f32 = splats.raw_labels[g * l..(g + 1) * l].iter().sum();
            // Anything non-finite (NaN/Inf parameters) is culled rather than blended. The SH
            // sum is tested before the clamp: `max(-inf, 0)` would hide an infinite
            // coefficient (the GPU projection tests the same sum).
            let check = p.check.0[i] + raw.x + raw.y + raw.z;
            if !(check + p.opacity.0[i] + label_sum).is_finite() {
                continue;
            }
            let j = group + i;
            out.means2d[j] = Vec2::new(p.mean2d[0].0[i], p.mean2d[1].0[i]);
            out.conics[j] = Vec3::new(p.conic[0].0[i], p.conic[1].0[i], p.conic[2].0[i]);
            out.depths[j] = p.depth.0[i];
            out.radii[j] = p.radius.0[i] as u32;
            let shifted = raw + Vec3::splat(0.5);
            out.colors[j] = shifted.max(Vec3::ZERO);
            out.color_pass[j] = (shifted.x >= 0.0) as u8
                | ((shifted.y >= 0.0) as u8) << 1
                | ((shifted.z >= 0.0) as u8) << 2;
            out.opacities[j] = p.opacity.0[i];
            out.extents[j] = Vec2::new(p.extent[0].0[i], p.extent[1].0[i]);
        }
    }
}

simd_dispatch!(
    /// [`project_chunk_impl`] for the best vector width this CPU has.
    project_chunk => project_chunk_impl(
        splats: &Splats,
        first: usize,
        frame: &CameraFrame,
        sh_degree: u32,
        alpha_threshold: f32,
        out: &mut ChunkOut<'_>,
    )
);

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
    resize(&mut out.color_pass, n);
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
        out.color_pass.par_chunks_mut(CHUNK),
        out.opacities.par_chunks_mut(CHUNK),
        out.extents.par_chunks_mut(CHUNK),
    )
        .into_par_iter()
        .enumerate()
        .for_each(
            |(chunk, (means2d, conics, depths, radii, colors, color_pass, opacities, extents))| {
                let mut chunk_out = ChunkOut {
                    means2d,
                    conics,
                    depths,
                    radii,
                    colors,
                    color_pass,
                    opacities,
                    extents,
                };
                let threshold = settings.alpha_threshold;
                project_chunk(
                    splats,
                    chunk * CHUNK,
                    frame,
                    sh_degree,
                    threshold,
                    &mut chunk_out,
                );
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
