//! Projection backward: screen-space gradients (2D mean, conic, colour, opacity, depth, labels)
//! of each Gaussian chained back to its parameters (mean, log-scale, un-normalised quaternion,
//! raw opacity, SH, raw labels). Per Gaussian, parallel over chunks; it must not touch pixels.

use glam::{Vec2, Vec3, Vec4};
use rayon::prelude::*;

use super::lanes::{F8, LANES, M8, build3, build3x3, build4, group_of};
use super::project::{GaussianLanes, M3, camera_space, dot3, world_to_camera_rows};
use super::{CameraFrame, Projected, RenderSettings, ScreenGrads, SplatGrads};
use crate::simd::simd_dispatch;
use crate::splats::Splats;
use crate::splats::sh::{eval_sh_backward_from_basis, sh_basis};

const CHUNK: usize = 1024;

/// Gradient of a rotation matrix built by `rotation_matrix` with respect to the unit
/// quaternion `(x, y, z, w)`; `v_r[row][col]` is dL/dR.
#[inline(always)]
fn rotation_matrix_backward(q: &[F8; 4], v_r: &M3) -> [F8; 4] {
    let [x, y, z, w] = *q;
    let g = |r: usize, c: usize| v_r[r][c];
    let v_w = 2.0 * (x * (g(2, 1) - g(1, 2)) + y * (g(0, 2) - g(2, 0)) + z * (g(1, 0) - g(0, 1)));
    let v_x = 2.0
        * (y * (g(0, 1) + g(1, 0)) + z * (g(0, 2) + g(2, 0)) - 2.0 * x * (g(1, 1) + g(2, 2))
            + w * (g(2, 1) - g(1, 2)));
    let v_y = 2.0
        * (x * (g(0, 1) + g(1, 0)) - 2.0 * y * (g(0, 0) + g(2, 2))
            + z * (g(1, 2) + g(2, 1))
            + w * (g(0, 2) - g(2, 0)));
    let v_z = 2.0
        * (x * (g(0, 2) + g(2, 0)) + y * (g(1, 2) + g(2, 1)) - 2.0 * z * (g(0, 0) + g(1, 1))
            + w * (g(1, 0) - g(0, 1)));
    [v_x, v_y, v_z, v_w]
}

/// The gradients of eight Gaussians that need no SH: everything but the colour path.
#[derive(Clone, Copy, Debug)]
struct GeometryGrads {
    v_raw_opacity: F8,
    v_norm: F8,
    /// False in a lane behind the near plane or with a zero rotation: only the fields above
    /// are meaningful there (the projection culled it, so this is only a safeguard).
    valid: M8,
    /// Through the 2D mean, the Jacobian and the depth (the SH direction part is added apart).
    v_mean: [F8; 3],
    v_log_scale: [F8; 3],
    v_rotation: [F8; 4],
    /// Unit view direction and camera distance, for the SH backward.
    dir: [F8; 3],
    dist: F8,
}

/// Entry `[r][c]` of dL/dΣ_cam = j0 j0ᵀ g00 + (j0 j1ᵀ + j1 j0ᵀ) g01 + j1 j1ᵀ g11.
#[inline(always)]
fn cov_cam_grad_entry(j0: &[F8; 3], j1: &[F8; 3], g: [F8; 3], r: usize, c: usize) -> F8 {
    j0[r] * j0[c] * g[0] + (j0[r] * j1[c] + j1[r] * j0[c]) * g[1] + j1[r] * j1[c] * g[2]
}

/// Projected values and screen-space gradients of eight Gaussians.
#[derive(Clone, Copy, Debug, Default)]
struct ScreenLanes {
    opacity: F8,
    conic: [F8; 3],
    v_m2: [F8; 2],
    v_conic: [F8; 3],
    v_opacity: F8,
    v_depth: F8,
}

impl ScreenLanes {
    /// Gaussians `start..start + live` (see [`group_of`]).
    #[inline(always)]
    fn gather(projected: &Projected, screen: &ScreenGrads, start: usize, live: usize) -> Self {
        let conics = group_of(&projected.conics, start, live);
        let v_conics = group_of(&screen.v_conics, start, live);
        let v_m2 = group_of(&screen.v_means2d, start, live);
        ScreenLanes {
            opacity: F8(group_of(&projected.opacities, start, live)),
            conic: build3(|a| F8::from_fn(|l| conics[l][a])),
            v_m2: [F8::from_fn(|l| v_m2[l].x), F8::from_fn(|l| v_m2[l].y)],
            v_conic: build3(|a| F8::from_fn(|l| v_conics[l][a])),
            v_opacity: F8(group_of(&screen.v_opacities, start, live)),
            v_depth: F8(group_of(&screen.v_depths, start, live)),
        }
    }
}

/// [`GeometryGrads`] of eight Gaussians (gsplat's `fully_fused_projection` backward, classic
/// mode), in the operation order of the scalar glam code this replaced.
#[inline(always)]
fn backward_geometry(x: &GaussianLanes, sc: &ScreenLanes, frame: &CameraFrame) -> GeometryGrads {
    let (v_m2, v_conic) = (sc.v_m2, sc.v_conic);
    let o = sc.opacity;
    let v_raw_opacity = sc.v_opacity * o * (1.0 - o);
    let (half_w, half_h) = (0.5 * frame.width as f32, 0.5 * frame.height as f32);
    let (nx, ny) = (v_m2[0] * half_w, v_m2[1] * half_h);
    let v_norm = (nx * nx + ny * ny).sqrt();
    let offset: [F8; 3] = build3(|i| x.mean[i] - frame.position[i]);
    let dist = dot3(&offset, &offset).sqrt();
    let dir = build3(|i| offset[i] / dist);

    let cs = camera_space(x, frame);
    // Conic = inverse(cov2d): dL/dcov2d = -C V C, V the symmetric gradient of the conic matrix
    // (the off-diagonal b appears twice in it, hence the halves).
    let [ca, cb, cc] = sc.conic;
    let (va, vb, vc) = (v_conic[0], 0.5 * v_conic[1], v_conic[2]);
    let cv00 = ca * va + cb * vb;
    let cv01 = ca * vb + cb * vc;
    let cv10 = cb * va + cc * vb;
    let cv11 = cb * vb + cc * vc;
    let g00 = -(cv00 * ca + cv01 * cb);
    let g01 = -(cv00 * cb + cv01 * cc);
    let g11 = -(cv10 * cb + cv11 * cc);
    // cov2d = J Σ_cam Jᵀ + blur.
    let (j0, j1, t0, t1) = (cs.j0, cs.j1, cs.t0, cs.t1);
    let v_j0: [F8; 3] = build3(|i| 2.0 * (g00 * t0[i] + g01 * t1[i]));
    let v_j1: [F8; 3] = build3(|i| 2.0 * (g01 * t0[i] + g11 * t1[i]));
    // Written out with a plain function: as a closure this entry was too large to be inlined.
    let e = |r, c| cov_cam_grad_entry(&j0, &j1, [g00, g01, g11], r, c);
    let v_cov_cam: M3 = [
        [e(0, 0), e(0, 1), e(0, 2)],
        [e(1, 0), e(1, 1), e(1, 2)],
        [e(2, 0), e(2, 1), e(2, 2)],
    ];
    // Σ_cam = ws wsᵀ, ws = W R S.
    let ws = cs.ws;
    let v_ws: M3 = build3x3(|r, c| {
        (v_cov_cam[r][0] * ws[0][c] + v_cov_cam[r][1] * ws[1][c] + v_cov_cam[r][2] * ws[2][c]) * 2.0
    });
    let w = world_to_camera_rows(frame);
    let v_m: M3 =
        build3x3(|r, c| w[0][r] * v_ws[0][c] + w[1][r] * v_ws[1][c] + w[2][r] * v_ws[2][c]);
    let (norm, q, rot, s) = (cs.norm, cs.q, cs.rot, cs.scale);
    let v_r: M3 = build3x3(|r, c| v_m[r][c] * s[c]);
    let v_s: [F8; 3] =
        build3(|c| rot[0][c] * v_m[0][c] + rot[1][c] * v_m[1][c] + rot[2][c] * v_m[2][c]);
    let v_log_scale: [F8; 3] = build3(|c| v_s[c] * s[c]);
    let v_qn = rotation_matrix_backward(&q, &v_r);
    let qn_dot = q[0] * v_qn[0] + q[1] * v_qn[1] + q[2] * v_qn[2] + q[3] * v_qn[3];
    let v_rotation: [F8; 4] = build4(|i| (v_qn[i] - q[i] * qn_dot) / norm);

    // Mean through the 2D mean, the Jacobian (gsplat's persp_proj_vjp) and the depth. Both
    // sides of each clamp test are computed and one selected, instead of branching.
    let p = cs.p_cam;
    let (fx, fy) = (frame.fx, frame.fy);
    let rz = 1.0 / p[2];
    let rz2 = rz * rz;
    let rz3 = rz2 * rz;
    let mut v_p = [
        fx * rz * v_m2[0],
        fy * rz * v_m2[1],
        -(fx * p[0] * v_m2[0] + fy * p[1] * v_m2[1]) * rz2,
    ];
    let (ux, uy) = (p[0] * rz, p[1] * rz);
    let tx = p[2] * ux.clamp(-frame.lim_x_neg, frame.lim_x_pos);
    let ty = p[2] * uy.clamp(-frame.lim_y_neg, frame.lim_y_pos);
    let in_x = ux.le(F8::splat(frame.lim_x_pos)) & ux.ge(F8::splat(-frame.lim_x_neg));
    let in_y = uy.le(F8::splat(frame.lim_y_pos)) & uy.ge(F8::splat(-frame.lim_y_neg));
    let x_inside = v_p[0] + -fx * rz2 * v_j0[2];
    let z_x_outside = v_p[2] + -fx * rz3 * v_j0[2] * tx;
    v_p[0] = F8::select(in_x, x_inside, v_p[0]);
    v_p[2] = F8::select(in_x, v_p[2], z_x_outside);
    let y_inside = v_p[1] + -fy * rz2 * v_j1[2];
    let z_y_outside = v_p[2] + -fy * rz3 * v_j1[2] * ty;
    v_p[1] = F8::select(in_y, y_inside, v_p[1]);
    v_p[2] = F8::select(in_y, v_p[2], z_y_outside);
    v_p[2] = v_p[2]
        + (-fx * rz2 * v_j0[0] - fy * rz2 * v_j1[1]
            + 2.0 * fx * tx * rz3 * v_j0[2]
            + 2.0 * fy * ty * rz3 * v_j1[2]);
    v_p[2] = v_p[2] + sc.v_depth;
    let v_mean: [F8; 3] = build3(|r| w[0][r] * v_p[0] + w[1][r] * v_p[1] + w[2][r] * v_p[2]);
    GeometryGrads {
        v_raw_opacity,
        v_norm,
        valid: cs.valid,
        v_mean,
        v_log_scale,
        v_rotation,
        dir,
        dist,
    }
}

/// The gradient slices of one chunk.
struct ChunkGrads<'a> {
    v_means: &'a mut [Vec3],
    v_log_scales: &'a mut [Vec3],
    v_rotations: &'a mut [Vec4],
    v_raw_opacities: &'a mut [f32],
    v_sh: &'a mut [f32],
    v_norm: &'a mut [f32],
    visible: &'a mut [bool],
}

/// Adds the gradients of the visible Gaussians `first..first + out.v_means.len()` into the
/// zeroed `out`, 8 at a time: the geometry of a group as one branch-free loop over its lanes
/// (vectorised), then the SH per lane and the masked adds. Missing lanes of the last group repeat its last Gaussian
/// and are dropped, so each Gaussian's bits do not depend on the chunking.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn backward_chunk_impl(
    splats: &Splats,
    first: usize,
    frame: &CameraFrame,
    settings: &RenderSettings,
    projected: &Projected,
    screen: &ScreenGrads,
    sh_degree: u32,
    out: &mut ChunkGrads<'_>,
) {
    let count = out.v_means.len();
    let k = splats.sh_coeffs() * 3;
    for group in (0..count).step_by(LANES) {
        let live = LANES.min(count - group);
        let x = GaussianLanes::gather(splats, first + group, live);
        let sc = ScreenLanes::gather(projected, screen, first + group, live);
        let lanes = backward_geometry(&x, &sc, frame);
        for i in 0..live {
            let (g, j) = (first + group + i, group + i);
            out.visible[j] = projected.radii[g] > 0;
            let v_color = screen.v_colors[g];
            // Everything is linear in these: a Gaussian no pixel used gets exact zeros (and
            // a culled one, whose lane may hold NaN, gets nothing).
            if !out.visible[j]
                || (screen.v_means2d[g] == Vec2::ZERO
                    && screen.v_conics[g] == Vec3::ZERO
                    && v_color == Vec3::ZERO
                    && screen.v_opacities[g] == 0.0
                    && screen.v_depths[g] == 0.0)
            {
                continue;
            }
            let lane3 = |v: &[F8; 3]| Vec3::new(v[0].0[i], v[1].0[i], v[2].0[i]);
            out.v_raw_opacities[j] += lanes.v_raw_opacity.0[i];
            out.v_norm[j] += lanes.v_norm.0[i];

            // Colour: max(SH(dir) + 0.5, 0), dir = normalize(mean - camera position).
            let (dir, dist) = (lane3(&lanes.dir), lanes.dist.0[i]);
            let coeffs = &splats.sh[g * k..(g + 1) * k];
            let mut basis = [0.0f32; 16];
            sh_basis(sh_degree, dir, &mut basis);
            let color_pass = projected.color_pass[g];
            let pass = |c: u8, v: f32| if color_pass & (1 << c) != 0 { v } else { 0.0 };
            let v_raw = Vec3::new(pass(0, v_color.x), pass(1, v_color.y), pass(2, v_color.z));
            let v_sh = &mut out.v_sh[j * k..(j + 1) * k];
            let v_dir = eval_sh_backward_from_basis(sh_degree, &basis, coeffs, dir, v_raw, v_sh);
            if settings.sh_direction_grad {
                out.v_means[j] += (v_dir - dir * dir.dot(v_dir)) / dist;
            }
            if lanes.valid.0[i] {
                out.v_means[j] += lane3(&lanes.v_mean);
                out.v_log_scales[j] += lane3(&lanes.v_log_scale);
                let r = &lanes.v_rotation;
                out.v_rotations[j] += Vec4::new(r[0].0[i], r[1].0[i], r[2].0[i], r[3].0[i]);
            }
        }
    }
}

simd_dispatch!(
    /// [`backward_chunk_impl`] for the best vector width this CPU has.
    backward_chunk => backward_chunk_impl(
        splats: &Splats,
        first: usize,
        frame: &CameraFrame,
        settings: &RenderSettings,
        projected: &Projected,
        screen: &ScreenGrads,
        sh_degree: u32,
        out: &mut ChunkGrads<'_>,
    )
);

/// Writes the parameter gradients of every Gaussian into `grads` (zero where no pixel used it).
pub(crate) fn project_backward(
    splats: &Splats,
    frame: &CameraFrame,
    settings: &RenderSettings,
    projected: &Projected,
    screen: &ScreenGrads,
    grads: &mut SplatGrads,
) {
    let k = splats.sh_coeffs() * 3;
    let sh_degree = settings.sh_degree.min(splats.sh_degree);
    (
        grads.v_means.par_chunks_mut(CHUNK),
        grads.v_log_scales.par_chunks_mut(CHUNK),
        grads.v_rotations.par_chunks_mut(CHUNK),
        grads.v_raw_opacities.par_chunks_mut(CHUNK),
        grads.v_sh.par_chunks_mut(CHUNK * k),
        grads.v_means2d_norm.par_chunks_mut(CHUNK),
        grads.visible.par_chunks_mut(CHUNK),
    )
        .into_par_iter()
        .enumerate()
        .for_each(
            |(
                chunk,
                (v_means, v_log_scales, v_rotations, v_raw_opacities, v_sh, v_norm, visible),
            )| {
                // Zeroed here, chunk by chunk while it is in cache, rather than by the caller
                // in one pass over every gradient array before the backward.
                v_means.fill(Vec3::ZERO);
                v_log_scales.fill(Vec3::ZERO);
                v_rotations.fill(Vec4::ZERO);
                v_raw_opacities.fill(0.0);
                v_sh.fill(0.0);
                v_norm.fill(0.0);
                let mut out = ChunkGrads {
                    v_means,
                    v_log_scales,
                    v_rotations,
                    v_raw_opacities,
                    v_sh,
                    v_norm,
                    visible,
                };
                let first = chunk * CHUNK;
                backward_chunk(
                    splats, first, frame, settings, projected, screen, sh_degree, &mut out,
                );
            },
        );
    let l = splats.label_channels;
    if l > 0 {
        for (i, v) in grads.v_raw_labels.iter_mut().enumerate() {
            let p = projected.labels[i];
            *v = screen.v_labels[i] * p * (1.0 - p);
        }
    }
}
