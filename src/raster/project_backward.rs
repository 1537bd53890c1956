//! Projection backward: screen-space gradients (2D mean, conic, colour, opacity, depth, labels)
//! of each Gaussian chained back to its parameters (mean, log-scale, un-normalised quaternion,
//! raw opacity, SH, raw labels). Per Gaussian, parallel over chunks; it must not touch pixels.

use glam::{Mat3, Vec3, Vec4};
use rayon::prelude::*;

use super::project::camera_space;
use super::{CameraFrame, Projected, RenderSettings, ScreenGrads, SplatGrads};
use crate::splats::Splats;
use crate::splats::sh::{eval_sh_backward_from_basis, eval_sh_from_basis, sh_basis};

const CHUNK: usize = 1024;

/// Gradient of a rotation matrix built by `rotation_matrix` with respect to the unit
/// quaternion `(x, y, z, w)`; `v_r` is dL/dR.
#[inline]
fn rotation_matrix_backward(q: glam::Quat, v_r: Mat3) -> Vec4 {
    let (x, y, z, w) = (q.x, q.y, q.z, q.w);
    // g(r, c) = dL/dR[row r][col c].
    let g = |r: usize, c: usize| v_r.col(c)[r];
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
    Vec4::new(v_x, v_y, v_z, v_w)
}

fn outer(a: Vec3, b: Vec3) -> Mat3 {
    Mat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// Parameter gradients of one visible Gaussian, added into the given slots.
#[allow(clippy::too_many_arguments)]
#[inline]
fn backward_one(
    splats: &Splats,
    g: usize,
    frame: &CameraFrame,
    settings: &RenderSettings,
    projected: &Projected,
    screen: &ScreenGrads,
    sh_degree: u32,
    v_mean: &mut Vec3,
    v_log_scale: &mut Vec3,
    v_rotation: &mut Vec4,
    v_raw_opacity: &mut f32,
    v_sh: &mut [f32],
    v_norm: &mut f32,
) {
    let v_m2 = screen.v_means2d[g];
    let v_conic = screen.v_conics[g];
    let v_color = screen.v_colors[g];
    let v_opacity = screen.v_opacities[g];
    let v_depth = screen.v_depths[g];
    // Everything below is linear in these: a Gaussian no pixel used gets exact zeros.
    if v_m2 == glam::Vec2::ZERO
        && v_conic == Vec3::ZERO
        && v_color == Vec3::ZERO
        && v_opacity == 0.0
        && v_depth == 0.0
    {
        return;
    }

    let o = projected.opacities[g];
    *v_raw_opacity += v_opacity * o * (1.0 - o);
    *v_norm +=
        (v_m2 * glam::Vec2::new(0.5 * frame.width as f32, 0.5 * frame.height as f32)).length();

    // Colour: max(SH(dir) + 0.5, 0), dir = normalize(mean - camera position).
    let mean = splats.means[g];
    let offset = mean - frame.position;
    let dist = offset.length();
    let dir = offset / dist;
    let k = splats.sh_coeffs() * 3;
    let coeffs = &splats.sh[g * k..(g + 1) * k];
    let mut basis = [0.0f32; 16];
    sh_basis(sh_degree, dir, &mut basis);
    let raw = eval_sh_from_basis(sh_degree, &basis, coeffs);
    let pass = |r: f32, v: f32| if r + 0.5 >= 0.0 { v } else { 0.0 };
    let v_raw = Vec3::new(
        pass(raw.x, v_color.x),
        pass(raw.y, v_color.y),
        pass(raw.z, v_color.z),
    );
    let v_dir = eval_sh_backward_from_basis(sh_degree, &basis, coeffs, dir, v_raw, v_sh);
    if settings.sh_direction_grad {
        *v_mean += (v_dir - dir * dir.dot(v_dir)) / dist;
    }

    let Some(cs) = camera_space(mean, splats.log_scales[g], splats.rotations[g], frame) else {
        return;
    };
    // Conic = inverse(cov2d): dL/dcov2d = -C V C, V the symmetric gradient of the conic matrix
    // (the off-diagonal b appears twice in it, hence the halves).
    let c = projected.conics[g];
    let (ca, cb, cc) = (c.x, c.y, c.z);
    let (va, vb, vc) = (v_conic.x, 0.5 * v_conic.y, v_conic.z);
    let cv00 = ca * va + cb * vb;
    let cv01 = ca * vb + cb * vc;
    let cv10 = cb * va + cc * vb;
    let cv11 = cb * vb + cc * vc;
    let g00 = -(cv00 * ca + cv01 * cb);
    let g01 = -(cv00 * cb + cv01 * cc);
    let g11 = -(cv10 * cb + cv11 * cc);
    // cov2d = J Σ_cam Jᵀ + blur.
    let v_j0 = 2.0 * (g00 * cs.t0 + g01 * cs.t1);
    let v_j1 = 2.0 * (g01 * cs.t0 + g11 * cs.t1);
    let v_cov_cam = outer(cs.j0, cs.j0) * g00
        + (outer(cs.j0, cs.j1) + outer(cs.j1, cs.j0)) * g01
        + outer(cs.j1, cs.j1) * g11;
    // Σ_cam = ws wsᵀ, ws = W R S.
    let v_ws = v_cov_cam * cs.ws * 2.0;
    let v_m = frame.world_to_camera.transpose() * v_ws;
    let (norm, q, r, s) = (cs.norm, cs.q, cs.rot, cs.scale);
    let v_r = Mat3::from_cols(v_m.x_axis * s.x, v_m.y_axis * s.y, v_m.z_axis * s.z);
    let v_s = Vec3::new(
        r.x_axis.dot(v_m.x_axis),
        r.y_axis.dot(v_m.y_axis),
        r.z_axis.dot(v_m.z_axis),
    );
    *v_log_scale += v_s * s;
    let v_qn = rotation_matrix_backward(q, v_r);
    let qn = Vec4::new(q.x, q.y, q.z, q.w);
    *v_rotation += (v_qn - qn * qn.dot(v_qn)) / norm;

    // Mean through the 2D mean, the Jacobian (gsplat's persp_proj_vjp) and the depth.
    let p = cs.p_cam;
    let (fx, fy) = (frame.fx, frame.fy);
    let rz = 1.0 / p.z;
    let rz2 = rz * rz;
    let rz3 = rz2 * rz;
    let mut v_p = Vec3::new(
        fx * rz * v_m2.x,
        fy * rz * v_m2.y,
        -(fx * p.x * v_m2.x + fy * p.y * v_m2.y) * rz2,
    );
    let tx = p.z * (p.x * rz).max(-frame.lim_x_neg).min(frame.lim_x_pos);
    let ty = p.z * (p.y * rz).max(-frame.lim_y_neg).min(frame.lim_y_pos);
    if p.x * rz <= frame.lim_x_pos && p.x * rz >= -frame.lim_x_neg {
        v_p.x += -fx * rz2 * v_j0.z;
    } else {
        v_p.z += -fx * rz3 * v_j0.z * tx;
    }
    if p.y * rz <= frame.lim_y_pos && p.y * rz >= -frame.lim_y_neg {
        v_p.y += -fy * rz2 * v_j1.z;
    } else {
        v_p.z += -fy * rz3 * v_j1.z * ty;
    }
    v_p.z += -fx * rz2 * v_j0.x - fy * rz2 * v_j1.y
        + 2.0 * fx * tx * rz3 * v_j0.z
        + 2.0 * fy * ty * rz3 * v_j1.z;
    v_p.z += v_depth;
    *v_mean += frame.world_to_camera.transpose() * v_p;
}

/// Adds the parameter gradients of every visible Gaussian into `grads`.
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
                for i in 0..v_means.len() {
                    let g = chunk * CHUNK + i;
                    visible[i] = projected.radii[g] > 0;
                    if !visible[i] {
                        continue;
                    }
                    backward_one(
                        splats,
                        g,
                        frame,
                        settings,
                        projected,
                        screen,
                        sh_degree,
                        &mut v_means[i],
                        &mut v_log_scales[i],
                        &mut v_rotations[i],
                        &mut v_raw_opacities[i],
                        &mut v_sh[i * k..(i + 1) * k],
                        &mut v_norm[i],
                    );
                }
            },
        );
    let l = splats.label_channels;
    if l > 0 {
        for (i, v) in grads.v_raw_labels.iter_mut().enumerate() {
            let p = projected.labels[i];
            *v += screen.v_labels[i] * p * (1.0 - p);
        }
    }
}
