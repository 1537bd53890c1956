//! The plain reference of the backward pass (see `reference.rs`): per pixel back to front in
//! gsplat's order (`rasterize_to_pixels_bwd`) to the screen-space gradients, then per Gaussian
//! through the projection (gsplat's `fully_fused_projection` backward) to every parameter.
//! Written to be read and to test the fast backward against; it must not be used for speed.

use glam::{Mat3, Vec2, Vec3, Vec4};

use super::reference::{
    CameraSpace, Pinhole, TileLists, blend_pixel, camera_space, from_rows, project, view_direction,
};
use super::{PixelGrads, Projected, RenderSettings, ScreenGrads, SplatGrads};
use crate::scene::Camera;
use crate::splats::Splats;
use crate::splats::sh::{eval_sh, eval_sh_backward};

/// Per-Gaussian sums of the screen-space gradients over every pixel, in f64: thousands of
/// pixels add into one Gaussian, and the reference should not carry the summation noise the
/// fast path is compared with.
#[derive(Clone, Copy, Debug, Default)]
struct ScreenSums {
    mean2d: [f64; 2],
    conic: [f64; 3],
    color: [f64; 3],
    opacity: f64,
    depth: f64,
}

/// The gradients of a loss with respect to a projected frame ([`ScreenGrads`]), given the
/// loss's gradients with respect to the blended image `v_out` (colour, and optionally alpha,
/// depth and label channels).
///
/// Per pixel, with `g` the output gradients, `s_i = c_i · g_rgb + z_i g_depth + p_i · g_labels`
/// what Gaussian `i` is worth per unit of weight `w_i = α_i T_i`, and `T_f` the final
/// transmittance (the background and alpha outputs depend on it):
/// `dL/dα_i = T_i s_i - (Σ_{j>i} w_j s_j + T_f (background · g_rgb - g_alpha)) / (1 - α_i)`,
/// since `T_j` for `j > i` and `T_f` each hold the factor `1 - α_i`. The sum over the Gaussians
/// behind `i` is gathered back to front, as gsplat does.
pub fn blend_backward(
    projected: &Projected,
    label_channels: usize,
    width: u32,
    height: u32,
    settings: &RenderSettings,
    v_out: &PixelGrads,
) -> ScreenGrads {
    let n = projected.radii.len();
    let l = label_channels;
    let pixels = (width * height) as usize;
    assert_eq!(v_out.color.len(), pixels * 3, "v_color has the wrong size");
    let mut sums = vec![ScreenSums::default(); n];
    let mut label_sums = vec![0.0f64; n * l];
    let tiles = TileLists::new(projected, width, height);
    for y in 0..height {
        for x in 0..width {
            let pixel = (y * width + x) as usize;
            let blend = blend_pixel(projected, &tiles, x, y, settings);
            let g_rgb = Vec3::from_slice(&v_out.color[pixel * 3..pixel * 3 + 3]);
            let g_alpha = v_out.alpha.map_or(0.0, |a| a[pixel]);
            let g_depth = v_out.depth.map_or(0.0, |d| d[pixel]);
            let g_labels = v_out.labels.map(|v| &v[pixel * l..(pixel + 1) * l]);
            let t_final = blend.final_transmittance;
            let final_term = t_final * (settings.background.dot(g_rgb) - g_alpha);
            // Σ_{j>i} w_j s_j: what lies behind the current Gaussian.
            let mut behind = 0.0f32;
            for b in blend.blended.iter().rev() {
                let g = b.gaussian;
                let probabilities = &projected.labels[g * l..(g + 1) * l];
                let label_worth: f32 = g_labels.map_or(0.0, |gl| {
                    probabilities.iter().zip(gl).map(|(p, v)| p * v).sum()
                });
                let worth =
                    projected.colors[g].dot(g_rgb) + projected.depths[g] * g_depth + label_worth;
                let weight = b.alpha * b.transmittance;
                let v_alpha = b.transmittance * worth - (behind + final_term) / (1.0 - b.alpha);
                behind += weight * worth;

                let sum = &mut sums[g];
                for c in 0..3 {
                    sum.color[c] += (weight * g_rgb[c]) as f64;
                }
                sum.depth += (weight * g_depth) as f64;
                if let Some(gl) = g_labels {
                    for (s, v) in label_sums[g * l..(g + 1) * l].iter_mut().zip(gl) {
                        *s += (weight * v) as f64;
                    }
                }
                // A clamped alpha is the constant alpha_max: nothing flows to the opacity or
                // the power (gsplat: `if (opac * vis <= 0.999f)`).
                if !(b.raw_alpha <= settings.alpha_max) {
                    continue;
                }
                // α = o · exp(-σ): dα/do = exp(-σ), dα/dσ = -α.
                sum.opacity += (b.falloff * v_alpha) as f64;
                let v_sigma = -b.raw_alpha * v_alpha;
                // σ = ½ (a dx² + c dy²) + b dx dy with d = mean2d - pixel centre.
                let (dx, dy) = (b.d.x, b.d.y);
                let conic = projected.conics[g];
                sum.conic[0] += (0.5 * v_sigma * dx * dx) as f64;
                sum.conic[1] += (v_sigma * dx * dy) as f64;
                sum.conic[2] += (0.5 * v_sigma * dy * dy) as f64;
                sum.mean2d[0] += (v_sigma * (conic.x * dx + conic.y * dy)) as f64;
                sum.mean2d[1] += (v_sigma * (conic.y * dx + conic.z * dy)) as f64;
            }
        }
    }
    let v3 = |v: [f64; 3]| Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32);
    ScreenGrads {
        v_means2d: sums
            .iter()
            .map(|s| Vec2::new(s.mean2d[0] as f32, s.mean2d[1] as f32))
            .collect(),
        v_conics: sums.iter().map(|s| v3(s.conic)).collect(),
        v_colors: sums.iter().map(|s| v3(s.color)).collect(),
        v_opacities: sums.iter().map(|s| s.opacity as f32).collect(),
        v_depths: sums.iter().map(|s| s.depth as f32).collect(),
        v_labels: label_sums.iter().map(|&v| v as f32).collect(),
    }
}

/// `Σ_rc a_rc b_rc`.
fn frobenius(a: Mat3, b: Mat3) -> f32 {
    a.x_axis.dot(b.x_axis) + a.y_axis.dot(b.y_axis) + a.z_axis.dot(b.z_axis)
}

/// dL/dq for the unit quaternion `(x, y, z, w)` given dL/dR, through the partial derivative
/// of each entry of `reference::rotation_matrix`.
fn rotation_matrix_backward(q: Vec4, v_r: Mat3) -> Vec4 {
    let (x, y, z, w) = (q.x, q.y, q.z, q.w);
    let d_dx = from_rows([
        [0.0, 2.0 * y, 2.0 * z],
        [2.0 * y, -4.0 * x, -2.0 * w],
        [2.0 * z, 2.0 * w, -4.0 * x],
    ]);
    let d_dy = from_rows([
        [-4.0 * y, 2.0 * x, 2.0 * w],
        [2.0 * x, 0.0, 2.0 * z],
        [-2.0 * w, 2.0 * z, -4.0 * y],
    ]);
    let d_dz = from_rows([
        [-4.0 * z, -2.0 * w, 2.0 * x],
        [2.0 * w, -4.0 * z, 2.0 * y],
        [2.0 * x, 2.0 * y, 0.0],
    ]);
    let d_dw = from_rows([
        [0.0, -2.0 * z, 2.0 * y],
        [2.0 * z, 0.0, -2.0 * x],
        [-2.0 * y, 2.0 * x, 0.0],
    ]);
    Vec4::new(
        frobenius(d_dx, v_r),
        frobenius(d_dy, v_r),
        frobenius(d_dz, v_r),
        frobenius(d_dw, v_r),
    )
}

/// The geometric gradients of one visible Gaussian: mean (through the 2D mean, the depth and
/// the Jacobian; the SH direction is added apart), log-scale and un-normalised rotation.
fn geometry_backward(
    cs: &CameraSpace,
    conic: Vec3,
    v_mean2d: Vec2,
    v_conic: Vec3,
    v_depth: f32,
    cam: &Pinhole,
) -> (Vec3, Vec3, Vec4) {
    // The conic is Σ'⁻¹: dL/dΣ' = -Σ'⁻¹ V Σ'⁻¹, V the gradient with respect to the conic's
    // symmetric matrix (its off-diagonal entry b appears twice, so each gets half of v_b).
    let inverse = glam::Mat2::from_cols(Vec2::new(conic.x, conic.y), Vec2::new(conic.y, conic.z));
    let v = glam::Mat2::from_cols(
        Vec2::new(v_conic.x, 0.5 * v_conic.y),
        Vec2::new(0.5 * v_conic.y, v_conic.z),
    );
    let v_cov2d = -(inverse * v * inverse);
    // Eq. 5, Σ' = J Σ_cam Jᵀ (+ blur), J 2×3: dL/dJ = 2 G J Σ_cam, dL/dΣ_cam = Jᵀ G J with
    // G = dL/dΣ' symmetric. Written with J's rows j0, j1 and G's entries.
    let [j0, j1] = cs.jacobian;
    let (g00, g01, g11) = (v_cov2d.x_axis.x, v_cov2d.y_axis.x, v_cov2d.y_axis.y);
    let (cov_j0, cov_j1) = (cs.cov_cam * j0, cs.cov_cam * j1);
    let v_j0 = 2.0 * (g00 * cov_j0 + g01 * cov_j1);
    let v_j1 = 2.0 * (g01 * cov_j0 + g11 * cov_j1);
    let outer = |a: Vec3, b: Vec3| Mat3::from_cols(a * b.x, a * b.y, a * b.z);
    let v_cov_cam =
        g00 * outer(j0, j0) + g01 * (outer(j0, j1) + outer(j1, j0)) + g11 * outer(j1, j1);
    // Σ_cam = W Σ Wᵀ, then eq. 6 with M = R S: Σ = M Mᵀ, so dL/dM = 2 (dL/dΣ) M.
    let w = cam.world_to_camera;
    let v_cov_world = w.transpose() * v_cov_cam * w;
    let m = cs.rotation * Mat3::from_diagonal(cs.scale);
    let v_m = 2.0 * v_cov_world * m;
    // M = R S: dL/dR = dL/dM S (scales R's columns), dL/ds_c = column c of R · column c of dL/dM.
    let v_rotation_matrix = v_m * Mat3::from_diagonal(cs.scale);
    let r = cs.rotation;
    let v_scale = Vec3::new(
        r.x_axis.dot(v_m.x_axis),
        r.y_axis.dot(v_m.y_axis),
        r.z_axis.dot(v_m.z_axis),
    );
    let v_log_scale = v_scale * cs.scale;
    // q̂ = q / |q|: dL/dq = (dL/dq̂ - q̂ (q̂ · dL/dq̂)) / |q|.
    let q = cs.unit_rotation;
    let v_unit = rotation_matrix_backward(q, v_rotation_matrix);
    let v_rotation = (v_unit - q * q.dot(v_unit)) / cs.rotation_norm;

    // The camera-space mean p feeds the 2D mean, the depth and the Jacobian.
    let p = cs.p;
    let (fx, fy, z) = (cam.fx, cam.fy, p.z);
    // mean2d = (fx x / z + cx, fy y / z + cy).
    let mut v_p = Vec3::new(
        fx / z * v_mean2d.x,
        fy / z * v_mean2d.y,
        -(fx * p.x * v_mean2d.x + fy * p.y * v_mean2d.y) / (z * z),
    );
    v_p.z += v_depth;
    // J = [[fx / z, 0, -fx u / z], [0, fy / z, -fy v / z]] with u = x / z clamped (likewise v).
    v_p.z += -fx / (z * z) * v_j0.x - fy / (z * z) * v_j1.y;
    // J02 = -fx x / z² where x / z is inside the limits, -fx u_limit / z where it is clamped.
    if cs.inside_x {
        v_p.x += -fx / (z * z) * v_j0.z;
        v_p.z += 2.0 * fx * p.x / (z * z * z) * v_j0.z;
    } else {
        v_p.z += fx * cs.clamped_uv.x / (z * z) * v_j0.z;
    }
    if cs.inside_y {
        v_p.y += -fy / (z * z) * v_j1.z;
        v_p.z += 2.0 * fy * p.y / (z * z * z) * v_j1.z;
    } else {
        v_p.z += fy * cs.clamped_uv.y / (z * z) * v_j1.z;
    }
    // p = W μ + t.
    let v_mean = w.transpose() * v_p;
    (v_mean, v_log_scale, v_rotation)
}

/// The gradients with respect to every parameter of `splats` (zero for a Gaussian projection
/// culled), from the screen-space gradients of the frame `projected` (both from
/// [`super::reference::project`] and [`blend_backward`] of the same splats, camera and
/// settings). `v_means2d_norm` is the fast path's densification statistic,
/// `|(v_mean2d.x · W / 2, v_mean2d.y · H / 2)|`; `visible` is `radius > 0`.
pub fn project_backward(
    splats: &Splats,
    camera: &Camera,
    settings: &RenderSettings,
    projected: &Projected,
    screen: &ScreenGrads,
) -> SplatGrads {
    let cam = Pinhole::new(camera, settings);
    let sh_degree = settings.sh_degree.min(splats.sh_degree);
    let k = splats.sh_coeffs() * 3;
    let l = splats.label_channels;
    let mut grads = SplatGrads::zeros(splats);
    for g in 0..splats.len() {
        if projected.radii[g] == 0 {
            continue;
        }
        grads.visible[g] = true;
        // A visible Gaussian passed these in `project`.
        let Some(cs) = camera_space(splats, g, &cam) else {
            continue;
        };
        // opacity = sigmoid(raw): dσ/dx = σ (1 - σ); the labels likewise.
        let opacity = projected.opacities[g];
        grads.v_raw_opacities[g] = screen.v_opacities[g] * opacity * (1.0 - opacity);
        for i in g * l..(g + 1) * l {
            let p = projected.labels[i];
            grads.v_raw_labels[i] = screen.v_labels[i] * p * (1.0 - p);
        }
        let v_mean2d = screen.v_means2d[g];
        let half_size = Vec2::new(0.5 * cam.width as f32, 0.5 * cam.height as f32);
        grads.v_means2d_norm[g] = (v_mean2d * half_size).length();

        let (v_mean, v_log_scale, v_rotation) = geometry_backward(
            &cs,
            projected.conics[g],
            v_mean2d,
            screen.v_conics[g],
            screen.v_depths[g],
            &cam,
        );
        grads.v_means[g] = v_mean;
        grads.v_log_scales[g] = v_log_scale;
        grads.v_rotations[g] = v_rotation;

        // Colour = max(SH(dir) + 0.5, 0): the gradient reaches the SH sum where the clamp
        // passed it (`>= 0`, as `Projected::color_pass` records it).
        let coeffs = &splats.sh[g * k..(g + 1) * k];
        let (dir, distance) = view_direction(splats.means[g], &cam);
        let shifted = eval_sh(sh_degree, coeffs, dir) + Vec3::splat(0.5);
        let v_color = screen.v_colors[g];
        let v_sh_sum = Vec3::select(shifted.cmpge(Vec3::ZERO), v_color, Vec3::ZERO);
        let v_dir = eval_sh_backward(
            sh_degree,
            coeffs,
            dir,
            v_sh_sum,
            &mut grads.v_sh[g * k..(g + 1) * k],
        );
        // dir = (μ - camera) / |μ - camera|: dL/dμ = (v - dir (dir · v)) / distance. gsplat
        // detaches this path; `sh_direction_grad` keeps it (the exact gradient).
        if settings.sh_direction_grad {
            grads.v_means[g] += (v_dir - dir * dir.dot(v_dir)) / distance;
        }
    }
    grads
}

/// The whole backward of one frame: projection, then [`blend_backward`] of the pixel
/// gradients `v_out`, then [`project_backward`]. Returns the parameter gradients and the
/// screen-space ones they came from.
pub fn backward(
    splats: &Splats,
    camera: &Camera,
    settings: &RenderSettings,
    v_out: &PixelGrads,
) -> (SplatGrads, ScreenGrads) {
    let projected = project(splats, camera, settings);
    let k = &camera.intrinsics;
    let screen = blend_backward(
        &projected,
        splats.label_channels,
        k.width,
        k.height,
        settings,
        v_out,
    );
    let grads = project_backward(splats, camera, settings, &projected, &screen);
    (grads, screen)
}
