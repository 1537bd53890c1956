// Stage 1, project + cull: one thread per Gaussian. EWA-projects the 3D Gaussian to a 2D conic
// (with the 0.3 px² low-pass of 3DGS), evaluates its SH colour for the view direction, counts the
// 16×16 tiles its 3-sigma box touches, and writes the depth sort key. Same maths as the CPU
// `raster` projection. Culled Gaussians get radius 0, zero tiles and the largest depth key.
// NaN/Inf anywhere in a Gaussian's parameters culls it: guards are written to fail on NaN, and
// because WGSL lets compilers assume floats are finite, finiteness is tested on the bit pattern.

const CULLED_KEY: u32 = 0xffffffffu;
const FAR_PLANE: f32 = 1e10;
const COV2D_BLUR: f32 = 0.3;
const ALPHA_THRESHOLD: f32 = 0.00392156862745098; // 1/255
const SH_C0: f32 = 0.28209479177387814;
const SH_C1: f32 = 0.4886025119029199;

@group(0) @binding(0) var<uniform> u: Uniforms;
// means (3N) | log_scales (3N) | rotations x,y,z,w (4N) | raw_opacities (N)
@group(0) @binding(1) var<storage, read> geometry: array<f32>;
@group(0) @binding(2) var<storage, read> sh: array<f32>;
@group(0) @binding(3) var<storage, read> raw_labels: array<f32>;
@group(0) @binding(4) var<storage, read_write> projected: array<ProjectedSplat>;
@group(0) @binding(5) var<storage, read_write> depth_keys: array<u32>;
@group(0) @binding(6) var<storage, read_write> depth_gids: array<u32>;
@group(0) @binding(7) var<storage, read_write> labels: array<f32>;

fn all_finite3(v: vec3<f32>) -> bool {
    return is_finite(v.x) && is_finite(v.y) && is_finite(v.z);
}

fn sigmoid(x: f32) -> f32 {
    return 1.0 / (1.0 + exp(-x));
}

fn read3(at: u32) -> vec3<f32> {
    return vec3<f32>(geometry[at], geometry[at + 1u], geometry[at + 2u]);
}

fn sh_coeff(base: u32, k: u32) -> vec3<f32> {
    let i = base + k * 3u;
    return vec3<f32>(sh[i], sh[i + 1u], sh[i + 2u]);
}

// Real SH up to degree 3 (3DGS / gsplat constants and signs): the raw sum; colour = max(sum + 0.5, 0)
// is taken by the caller after the finiteness test (max(-inf, 0) would hide an infinite coefficient).
fn sh_color(g: u32, dir: vec3<f32>) -> vec3<f32> {
    let base = g * u.sh_coeffs * 3u;
    var c = SH_C0 * sh_coeff(base, 0u);
    if u.sh_degree >= 1u {
        let x = dir.x;
        let y = dir.y;
        let z = dir.z;
        c += SH_C1 * (-y * sh_coeff(base, 1u) + z * sh_coeff(base, 2u) - x * sh_coeff(base, 3u));
        if u.sh_degree >= 2u {
            let xx = x * x;
            let yy = y * y;
            let zz = z * z;
            let xy = x * y;
            let yz = y * z;
            let xz = x * z;
            c += 1.0925484305920792 * xy * sh_coeff(base, 4u)
                + -1.0925484305920792 * yz * sh_coeff(base, 5u)
                + 0.31539156525252005 * (2.0 * zz - xx - yy) * sh_coeff(base, 6u)
                + -1.0925484305920792 * xz * sh_coeff(base, 7u)
                + 0.5462742152960396 * (xx - yy) * sh_coeff(base, 8u);
            if u.sh_degree >= 3u {
                c += -0.5900435899266435 * y * (3.0 * xx - yy) * sh_coeff(base, 9u)
                    + 2.890611442640554 * xy * z * sh_coeff(base, 10u)
                    + -0.4570457994644658 * y * (4.0 * zz - xx - yy) * sh_coeff(base, 11u)
                    + 0.3731763325901154 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * sh_coeff(base, 12u)
                    + -0.4570457994644658 * x * (4.0 * zz - xx - yy) * sh_coeff(base, 13u)
                    + 1.445305721320277 * z * (xx - yy) * sh_coeff(base, 14u)
                    + -0.5900435899266435 * x * (xx - 3.0 * yy) * sh_coeff(base, 15u);
            }
        }
    }
    return c;
}

// Tiles [x0, x1) × [y0, y1) as (x0, y0, x1, y1): gsplat's radius rectangle intersected with the
// tiles holding a pixel centre of the image inside `extent` (raster::tile_rect, the same f32
// operations).
fn tile_rect(xy: vec2<f32>, r: f32, extent: vec2<f32>) -> vec4<u32> {
    if !(extent.x > 0.0) || !(extent.y > 0.0) || u.img_size.x == 0u || u.img_size.y == 0u {
        return vec4<u32>(0u);
    }
    let tb = vec2<f32>(u.tile_bounds);
    let g0 = clamp(floor((xy - vec2<f32>(r)) / TILE_SIZE), vec2<f32>(0.0), tb);
    let g1 = clamp(ceil((xy + vec2<f32>(r)) / TILE_SIZE), vec2<f32>(0.0), tb);
    let p0 = max(ceil(xy - extent - vec2<f32>(0.5)), vec2<f32>(0.0));
    let p1 = min(floor(xy + extent - vec2<f32>(0.5)), vec2<f32>(u.img_size - vec2<u32>(1u)));
    // `!(<=)` also drops NaN.
    if !(p0.x <= p1.x) || !(p0.y <= p1.y) {
        return vec4<u32>(0u);
    }
    let e0 = clamp(floor(p0 / TILE_SIZE), vec2<f32>(0.0), tb);
    let e1 = clamp(floor(p1 / TILE_SIZE) + vec2<f32>(1.0), vec2<f32>(0.0), tb);
    let lo = vec2<u32>(max(g0, e0));
    let hi = vec2<u32>(min(g1, e1));
    if lo.x >= hi.x || lo.y >= hi.y {
        return vec4<u32>(0u);
    }
    return vec4<u32>(lo, hi);
}

fn culled() -> ProjectedSplat {
    var p: ProjectedSplat;
    p.xy = vec2<f32>(0.0);
    p.depth = 0.0;
    p.opacity = 0.0;
    p.conic = vec3<f32>(0.0);
    p.radius = 0u;
    p.color = vec3<f32>(0.0);
    p.tiles = 0u;
    p.rect_x = 0u;
    p.rect_y = 0u;
    p.pad0 = 0u;
    p.pad1 = 0u;
    return p;
}

@compute @workgroup_size(256)
fn project(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let g = (wg.x + wg.y * nwg.x) * 256u + t;
    if g >= u.num_gaussians {
        return;
    }
    depth_gids[g] = g;
    projected[g] = culled();
    depth_keys[g] = CULLED_KEY;

    let mean = read3(3u * g);
    let p_cam = vec3<f32>(dot(u.rot0.xyz, mean), dot(u.rot1.xyz, mean), dot(u.rot2.xyz, mean)) + u.trans.xyz;
    // `!(z > near)` also culls NaN.
    if !(p_cam.z > u.near) || !(p_cam.z < FAR_PLANE) || !all_finite3(p_cam) {
        return;
    }

    let scale = exp(read3(u.log_scales_at + 3u * g));
    let qa = u.rotations_at + 4u * g;
    let q_raw = vec4<f32>(geometry[qa], geometry[qa + 1u], geometry[qa + 2u], geometry[qa + 3u]);
    let q_len2 = dot(q_raw, q_raw);
    if !(q_len2 > 0.0) || !is_finite(q_len2) {
        return;
    }
    let q = q_raw * (1.0 / sqrt(q_len2));
    let x = q.x;
    let y = q.y;
    let z = q.z;
    let w = q.w;
    // Columns of the rotation matrix of q (x, y, z, w).
    let r = mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
        vec3<f32>(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
        vec3<f32>(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)),
    );
    let m = mat3x3<f32>(r[0] * scale.x, r[1] * scale.y, r[2] * scale.z);
    // World-to-camera rotation as a matrix (columns from the uniform rows); Σ_cam = (W M)(W M)ᵀ.
    let w2c = transpose(mat3x3<f32>(u.rot0.xyz, u.rot1.xyz, u.rot2.xyz));
    let ws = w2c * m;
    let cov_cam = ws * transpose(ws);

    // EWA: Jacobian of the perspective projection at the mean, x/z and y/z clamped to 1.3× the
    // field of view as gsplat (and raster::CameraFrame) do.
    let fx = u.focal.x;
    let fy = u.focal.y;
    let width = f32(u.img_size.x);
    let height = f32(u.img_size.y);
    let tan_fovx = 0.5 * width / fx;
    let tan_fovy = 0.5 * height / fy;
    let lim_x_pos = (width - u.principal.x) / fx + 0.3 * tan_fovx;
    let lim_x_neg = u.principal.x / fx + 0.3 * tan_fovx;
    let lim_y_pos = (height - u.principal.y) / fy + 0.3 * tan_fovy;
    let lim_y_neg = u.principal.y / fy + 0.3 * tan_fovy;
    let rz = 1.0 / p_cam.z;
    let rz2 = rz * rz;
    let tx = p_cam.z * min(max(p_cam.x * rz, -lim_x_neg), lim_x_pos);
    let ty = p_cam.z * min(max(p_cam.y * rz, -lim_y_neg), lim_y_pos);
    let j0 = vec3<f32>(fx * rz, 0.0, -fx * tx * rz2);
    let j1 = vec3<f32>(0.0, fy * rz, -fy * ty * rz2);
    let t0 = cov_cam * j0;
    let t1 = cov_cam * j1;
    // 0.3 px² low-pass: the EWA screen-space dilation of 3DGS.
    let a = dot(j0, t0) + COV2D_BLUR;
    let b = dot(j0, t1);
    let c = dot(j1, t1) + COV2D_BLUR;
    let det = a * c - b * b;
    if !(det > 0.0) || !is_finite(det) {
        return;
    }
    let inv_det = 1.0 / det;
    let conic = vec3<f32>(c * inv_det, -b * inv_det, a * inv_det);
    // 3 sigma of the larger eigenvalue; the 0.01 floor is gsplat's.
    let mid = 0.5 * (a + c);
    let lambda = mid + sqrt(max(mid * mid - det, 0.01));
    let radius_f = ceil(3.0 * sqrt(lambda));
    let xy = vec2<f32>(fx * p_cam.x * rz + u.principal.x, fy * p_cam.y * rz + u.principal.y);
    if !(radius_f > 0.0) || !(xy.x + radius_f > 0.0) || !(xy.x - radius_f < width)
        || !(xy.y + radius_f > 0.0) || !(xy.y - radius_f < height) || !is_finite(radius_f) {
        return;
    }
    let opacity = sigmoid(geometry[u.opacities_at + g]);
    // opacity · exp(-power) >= 1/255  <=>  power <= ln(255 · opacity): the half-sizes of that
    // ellipse's box, with raster::project's safety margins.
    var power_max = -1.0;
    if opacity >= ALPHA_THRESHOLD {
        power_max = log(opacity / ALPHA_THRESHOLD) + 1e-3;
    }
    var extent = vec2<f32>(0.0);
    if power_max > 0.0 {
        extent = vec2<f32>(sqrt(2.0 * power_max * a) * 1.001 + 0.01, sqrt(2.0 * power_max * c) * 1.001 + 0.01);
    }
    let dir = normalize(mean - u.cam_pos.xyz);
    let sh_sum = sh_color(g, dir);
    let color = max(sh_sum + vec3<f32>(0.5), vec3<f32>(0.0));
    var finite = all_finite3(conic) && is_finite(xy.x) && is_finite(xy.y) && all_finite3(sh_sum)
        && is_finite(opacity) && is_finite(extent.x) && is_finite(extent.y);
    for (var k = 0u; k < u.label_channels; k = k + 1u) {
        finite = finite && is_finite(raw_labels[g * u.label_channels + k]);
    }
    if !finite {
        return;
    }
    for (var k = 0u; k < u.label_channels; k = k + 1u) {
        labels[g * u.label_channels + k] = sigmoid(raw_labels[g * u.label_channels + k]);
    }
    let rect = tile_rect(xy, radius_f, extent);
    let tiles = (rect.z - rect.x) * (rect.w - rect.y);

    var out: ProjectedSplat;
    out.xy = xy;
    out.depth = p_cam.z;
    out.opacity = opacity;
    out.conic = conic;
    out.radius = u32(radius_f);
    out.color = color;
    out.tiles = tiles;
    out.rect_x = rect.x | (rect.z << 16u);
    out.rect_y = rect.y | (rect.w << 16u);
    out.pad0 = 0u;
    out.pad1 = 0u;
    projected[g] = out;
    // Positive floats order like their bit patterns; Gaussians in no tile are not sorted.
    if tiles > 0u {
        depth_keys[g] = bitcast<u32>(p_cam.z);
    }
}
