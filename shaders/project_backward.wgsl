// Backward of stage 1 (project), gsplat's `fully_fused_projection` backward: one thread per
// Gaussian, from its summed screen-space gradients (rasterize_backward) to every parameter, the
// same chain as `raster::reference_backward::project_backward`: conic → 2D covariance → J and
// Σ_cam → Σ = M Mᵀ → scale and rotation; 2D mean, depth and J → camera-space mean → mean; colour
// → SH coefficients (and, when asked, the view direction → mean); sigmoids → opacity and labels.
// Per Gaussian it writes `param_grads` (stride 16: v_mean xyz, v_log_scale xyz, v_rotation xyzw,
// v_raw_opacity, |v_mean2d · (W/2, H/2)|, radius bits, 3 unused), `v_sh` and `v_raw_labels`;
// culled Gaussians get zeros. `Uniforms.sh_direction_grad` keeps the direction path (exact) or
// drops it (gsplat).

const SCREEN_FLOATS: u32 = 10u;
const PARAM_FLOATS: u32 = 16u;
const SH_C0: f32 = 0.28209479177387814;
const SH_C1: f32 = 0.4886025119029199;
const SH_C2_0: f32 = 1.0925484305920792;
const SH_C2_1: f32 = -1.0925484305920792;
const SH_C2_2: f32 = 0.31539156525252005;
const SH_C2_3: f32 = -1.0925484305920792;
const SH_C2_4: f32 = 0.5462742152960396;
const SH_C3_0: f32 = -0.5900435899266435;
const SH_C3_1: f32 = 2.890611442640554;
const SH_C3_2: f32 = -0.4570457994644658;
const SH_C3_3: f32 = 0.3731763325901154;
const SH_C3_4: f32 = -0.4570457994644658;
const SH_C3_5: f32 = 1.445305721320277;
const SH_C3_6: f32 = -0.5900435899266435;

@group(0) @binding(0) var<uniform> u: Uniforms;
// means (3C) | log_scales (3C) | rotations x,y,z,w (4C) | raw_opacities (C)
@group(0) @binding(1) var<storage, read> geometry: array<f32>;
@group(0) @binding(2) var<storage, read> sh: array<f32>;
@group(0) @binding(3) var<storage, read> projected: array<ProjectedSplat>;
@group(0) @binding(4) var<storage, read> labels: array<f32>;
@group(0) @binding(5) var<storage, read> screen_grads: array<f32>;
@group(0) @binding(6) var<storage, read_write> param_grads: array<f32>;
@group(0) @binding(7) var<storage, read_write> v_sh: array<f32>;
@group(0) @binding(8) var<storage, read_write> v_raw_labels: array<f32>;

fn read3(at: u32) -> vec3<f32> {
    return vec3<f32>(geometry[at], geometry[at + 1u], geometry[at + 2u]);
}

fn outer(a: vec3<f32>, b: vec3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(a * b.x, a * b.y, a * b.z);
}

// SH basis Y_k(dir) and its partial derivatives (components independent), up to `degree`.
fn sh_basis(degree: u32, d: vec3<f32>, k: u32) -> f32 {
    let x = d.x;
    let y = d.y;
    let z = d.z;
    switch k {
        case 0u: { return SH_C0; }
        case 1u: { return -SH_C1 * y; }
        case 2u: { return SH_C1 * z; }
        case 3u: { return -SH_C1 * x; }
        case 4u: { return SH_C2_0 * x * y; }
        case 5u: { return SH_C2_1 * y * z; }
        case 6u: { return SH_C2_2 * (2.0 * z * z - x * x - y * y); }
        case 7u: { return SH_C2_3 * x * z; }
        case 8u: { return SH_C2_4 * (x * x - y * y); }
        case 9u: { return SH_C3_0 * y * (3.0 * x * x - y * y); }
        case 10u: { return SH_C3_1 * x * y * z; }
        case 11u: { return SH_C3_2 * y * (4.0 * z * z - x * x - y * y); }
        case 12u: { return SH_C3_3 * z * (2.0 * z * z - 3.0 * x * x - 3.0 * y * y); }
        case 13u: { return SH_C3_4 * x * (4.0 * z * z - x * x - y * y); }
        case 14u: { return SH_C3_5 * z * (x * x - y * y); }
        default: { return SH_C3_6 * x * (x * x - 3.0 * y * y); }
    }
}

fn sh_basis_derivative(d: vec3<f32>, k: u32) -> vec3<f32> {
    let x = d.x;
    let y = d.y;
    let z = d.z;
    let xx = x * x;
    let yy = y * y;
    let zz = z * z;
    switch k {
        case 0u: { return vec3<f32>(0.0); }
        case 1u: { return vec3<f32>(0.0, -SH_C1, 0.0); }
        case 2u: { return vec3<f32>(0.0, 0.0, SH_C1); }
        case 3u: { return vec3<f32>(-SH_C1, 0.0, 0.0); }
        case 4u: { return SH_C2_0 * vec3<f32>(y, x, 0.0); }
        case 5u: { return SH_C2_1 * vec3<f32>(0.0, z, y); }
        case 6u: { return SH_C2_2 * vec3<f32>(-2.0 * x, -2.0 * y, 4.0 * z); }
        case 7u: { return SH_C2_3 * vec3<f32>(z, 0.0, x); }
        case 8u: { return SH_C2_4 * vec3<f32>(2.0 * x, -2.0 * y, 0.0); }
        case 9u: { return SH_C3_0 * vec3<f32>(6.0 * x * y, 3.0 * xx - 3.0 * yy, 0.0); }
        case 10u: { return SH_C3_1 * vec3<f32>(y * z, x * z, x * y); }
        case 11u: { return SH_C3_2 * vec3<f32>(-2.0 * x * y, 4.0 * zz - xx - 3.0 * yy, 8.0 * y * z); }
        case 12u: { return SH_C3_3 * vec3<f32>(-6.0 * x * z, -6.0 * y * z, 6.0 * zz - 3.0 * xx - 3.0 * yy); }
        case 13u: { return SH_C3_4 * vec3<f32>(4.0 * zz - 3.0 * xx - yy, -2.0 * x * y, 8.0 * x * z); }
        case 14u: { return SH_C3_5 * vec3<f32>(2.0 * x * z, -2.0 * y * z, xx - yy); }
        default: { return SH_C3_6 * vec3<f32>(3.0 * xx - 3.0 * yy, -6.0 * x * y, 0.0); }
    }
}

fn zero_gradients(g: u32, radius: u32) {
    for (var i = 0u; i < PARAM_FLOATS; i = i + 1u) {
        param_grads[g * PARAM_FLOATS + i] = 0.0;
    }
    param_grads[g * PARAM_FLOATS + 12u] = bitcast<f32>(radius);
    let k = u.sh_coeffs * 3u;
    for (var i = 0u; i < k; i = i + 1u) {
        v_sh[g * k + i] = 0.0;
    }
    for (var i = 0u; i < u.label_channels; i = i + 1u) {
        v_raw_labels[g * u.label_channels + i] = 0.0;
    }
}

@compute @workgroup_size(256)
fn project_backward(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let g = (wg.x + wg.y * nwg.x) * 256u + t;
    if g >= u.num_gaussians {
        return;
    }
    let p = projected[g];
    zero_gradients(g, p.radius);
    if p.radius == 0u {
        return;
    }
    let lcs = u.label_channels;
    let sg = g * (SCREEN_FLOATS + lcs);
    let v_mean2d = vec2<f32>(screen_grads[sg], screen_grads[sg + 1u]);
    let v_conic = vec3<f32>(screen_grads[sg + 2u], screen_grads[sg + 3u], screen_grads[sg + 4u]);
    let v_color = vec3<f32>(screen_grads[sg + 5u], screen_grads[sg + 6u], screen_grads[sg + 7u]);
    let v_opacity = screen_grads[sg + 8u];
    let v_depth = screen_grads[sg + 9u];
    let out = g * PARAM_FLOATS;

    // opacity = sigmoid(raw), labels likewise: dσ/dx = σ (1 - σ).
    param_grads[out + 10u] = v_opacity * p.opacity * (1.0 - p.opacity);
    for (var k = 0u; k < lcs; k = k + 1u) {
        let prob = labels[g * lcs + k];
        v_raw_labels[g * lcs + k] = screen_grads[sg + SCREEN_FLOATS + k] * prob * (1.0 - prob);
    }
    let width = f32(u.img_size.x);
    let height = f32(u.img_size.y);
    param_grads[out + 11u] = length(v_mean2d * vec2<f32>(0.5 * width, 0.5 * height));

    // Camera space again, as `project` computed it (a visible Gaussian passed its guards).
    let mean = read3(3u * g);
    let w2c = transpose(mat3x3<f32>(u.rot0.xyz, u.rot1.xyz, u.rot2.xyz));
    let p_cam = w2c * mean + u.trans.xyz;
    let scale = exp(read3(u.log_scales_at + 3u * g));
    let qa = u.rotations_at + 4u * g;
    let q_raw = vec4<f32>(geometry[qa], geometry[qa + 1u], geometry[qa + 2u], geometry[qa + 3u]);
    let q_norm = sqrt(dot(q_raw, q_raw));
    let q = q_raw / q_norm;
    let x = q.x;
    let y = q.y;
    let z = q.z;
    let w = q.w;
    let r = mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
        vec3<f32>(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
        vec3<f32>(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)),
    );
    let m = mat3x3<f32>(r[0] * scale.x, r[1] * scale.y, r[2] * scale.z);
    let ws = w2c * m;
    let cov_cam = ws * transpose(ws);
    let fx = u.focal.x;
    let fy = u.focal.y;
    let tan_fovx = 0.5 * width / fx;
    let tan_fovy = 0.5 * height / fy;
    let lim_x_pos = (width - u.principal.x) / fx + 0.3 * tan_fovx;
    let lim_x_neg = u.principal.x / fx + 0.3 * tan_fovx;
    let lim_y_pos = (height - u.principal.y) / fy + 0.3 * tan_fovy;
    let lim_y_neg = u.principal.y / fy + 0.3 * tan_fovy;
    let rz = 1.0 / p_cam.z;
    let rz2 = rz * rz;
    let u_raw = p_cam.x * rz;
    let v_raw = p_cam.y * rz;
    let u_clamped = min(max(u_raw, -lim_x_neg), lim_x_pos);
    let v_clamped = min(max(v_raw, -lim_y_neg), lim_y_pos);
    let j0 = vec3<f32>(fx * rz, 0.0, -fx * u_clamped * rz);
    let j1 = vec3<f32>(0.0, fy * rz, -fy * v_clamped * rz);

    // conic = Σ'⁻¹: dL/dΣ' = -Σ'⁻¹ V Σ'⁻¹ (V symmetric: the off-diagonal b appears twice).
    let conic = p.conic;
    let inverse = mat2x2<f32>(vec2<f32>(conic.x, conic.y), vec2<f32>(conic.y, conic.z));
    let v_sym = mat2x2<f32>(vec2<f32>(v_conic.x, 0.5 * v_conic.y), vec2<f32>(0.5 * v_conic.y, v_conic.z));
    let v_cov2d = (inverse * v_sym * inverse) * -1.0;
    let g00 = v_cov2d[0].x;
    let g01 = v_cov2d[1].x;
    let g11 = v_cov2d[1].y;
    // Σ' = J Σ_cam Jᵀ: dL/dJ rows and dL/dΣ_cam.
    let cov_j0 = cov_cam * j0;
    let cov_j1 = cov_cam * j1;
    let v_j0 = 2.0 * (g00 * cov_j0 + g01 * cov_j1);
    let v_j1 = 2.0 * (g01 * cov_j0 + g11 * cov_j1);
    let v_cov_cam = g00 * outer(j0, j0) + g01 * (outer(j0, j1) + outer(j1, j0)) + g11 * outer(j1, j1);
    // Σ_cam = W Σ Wᵀ; Σ = M Mᵀ: dL/dM = 2 (dL/dΣ) M; M = R S.
    let v_cov_world = transpose(w2c) * v_cov_cam * w2c;
    let v_m = 2.0 * v_cov_world * m;
    let v_scale = vec3<f32>(dot(r[0], v_m[0]), dot(r[1], v_m[1]), dot(r[2], v_m[2]));
    let v_log_scale = v_scale * scale;
    // dL/dR = dL/dM S; entry (row, col) of a WGSL matrix is [col][row].
    let vr = mat3x3<f32>(v_m[0] * scale.x, v_m[1] * scale.y, v_m[2] * scale.z);
    let v00 = vr[0].x;
    let v10 = vr[0].y;
    let v20 = vr[0].z;
    let v01 = vr[1].x;
    let v11 = vr[1].y;
    let v21 = vr[1].z;
    let v02 = vr[2].x;
    let v12 = vr[2].y;
    let v22 = vr[2].z;
    let v_unit = vec4<f32>(
        2.0 * y * (v01 + v10) + 2.0 * z * (v02 + v20) + 2.0 * w * (v21 - v12) - 4.0 * x * (v11 + v22),
        -4.0 * y * (v00 + v22) + 2.0 * x * (v01 + v10) + 2.0 * w * (v02 - v20) + 2.0 * z * (v12 + v21),
        -4.0 * z * (v00 + v11) + 2.0 * w * (v10 - v01) + 2.0 * x * (v02 + v20) + 2.0 * y * (v12 + v21),
        2.0 * z * (v10 - v01) + 2.0 * y * (v02 - v20) + 2.0 * x * (v21 - v12),
    );
    // q̂ = q / |q|.
    let v_rotation = (v_unit - q * dot(q, v_unit)) / q_norm;

    // The camera-space mean feeds the 2D mean, the depth and J.
    let pz = p_cam.z;
    var v_p = vec3<f32>(
        fx * rz * v_mean2d.x,
        fy * rz * v_mean2d.y,
        -(fx * p_cam.x * v_mean2d.x + fy * p_cam.y * v_mean2d.y) * rz2,
    );
    v_p.z += v_depth;
    v_p.z += -fx * rz2 * v_j0.x - fy * rz2 * v_j1.y;
    if -lim_x_neg <= u_raw && u_raw <= lim_x_pos {
        v_p.x += -fx * rz2 * v_j0.z;
        v_p.z += 2.0 * fx * p_cam.x * rz2 * rz * v_j0.z;
    } else {
        v_p.z += fx * u_clamped * rz2 * v_j0.z;
    }
    if -lim_y_neg <= v_raw && v_raw <= lim_y_pos {
        v_p.y += -fy * rz2 * v_j1.z;
        v_p.z += 2.0 * fy * p_cam.y * rz2 * rz * v_j1.z;
    } else {
        v_p.z += fy * v_clamped * rz2 * v_j1.z;
    }
    var v_mean = transpose(w2c) * v_p;

    // colour = max(SH(dir) + 0.5, 0): the gradient reaches the SH where the clamp passed it.
    let offset = mean - u.cam_pos.xyz;
    let distance = length(offset);
    let dir = offset / distance;
    let degree = u.sh_degree;
    let active_coeffs = (degree + 1u) * (degree + 1u);
    let base = g * u.sh_coeffs * 3u;
    var sh_sum = vec3<f32>(0.0);
    for (var k = 0u; k < active_coeffs; k = k + 1u) {
        let c = vec3<f32>(sh[base + 3u * k], sh[base + 3u * k + 1u], sh[base + 3u * k + 2u]);
        sh_sum += sh_basis(degree, dir, k) * c;
    }
    let shifted = sh_sum + vec3<f32>(0.5);
    let v_sh_sum = select(vec3<f32>(0.0), v_color, shifted >= vec3<f32>(0.0));
    var v_dir = vec3<f32>(0.0);
    for (var k = 0u; k < active_coeffs; k = k + 1u) {
        let b = sh_basis(degree, dir, k);
        v_sh[base + 3u * k] = b * v_sh_sum.x;
        v_sh[base + 3u * k + 1u] = b * v_sh_sum.y;
        v_sh[base + 3u * k + 2u] = b * v_sh_sum.z;
        let c = vec3<f32>(sh[base + 3u * k], sh[base + 3u * k + 1u], sh[base + 3u * k + 2u]);
        v_dir += sh_basis_derivative(dir, k) * dot(c, v_sh_sum);
    }
    if u.sh_direction_grad != 0u {
        v_mean += (v_dir - dir * dot(dir, v_dir)) / distance;
    }

    param_grads[out] = v_mean.x;
    param_grads[out + 1u] = v_mean.y;
    param_grads[out + 2u] = v_mean.z;
    param_grads[out + 3u] = v_log_scale.x;
    param_grads[out + 4u] = v_log_scale.y;
    param_grads[out + 5u] = v_log_scale.z;
    param_grads[out + 6u] = v_rotation.x;
    param_grads[out + 7u] = v_rotation.y;
    param_grads[out + 8u] = v_rotation.z;
    param_grads[out + 9u] = v_rotation.w;
}
