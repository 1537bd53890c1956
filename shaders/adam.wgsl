// Adam on the GPU, fused over every parameter group of one Gaussian per thread, the same update
// as `train::adam` (3DGS's optimiser): per group a step size lr / (1 - β1^t) and 1 / sqrt(1 - β2^t)
// from the host; frozen Gaussians and, as the CPU trainer asks ("visible Adam"), Gaussians the
// frame culled keep their parameters and moments. It also accumulates density control's
// statistics for visible Gaussians (`Densifier::accumulate`: |v_mean2d| sum, count, largest
// radius) and ORs a bit per group into word 0 when a gradient it applied (bit g) or a parameter
// it wrote (bit 8 + g) is not finite, so the host reads 4 bytes a step instead of the model.
// `common.wgsl` is prepended for `is_finite`.

struct AdamUniforms {
    // Per group (means, log_scales, rotations, raw_opacities, sh_dc, sh_rest, raw_labels):
    // lr / bias1, 1 / bias2_sqrt, 1 if the group steps, unused.
    groups: array<vec4<f32>, 7>,
    beta1: f32,
    beta2: f32,
    eps: f32,
    num_gaussians: u32,
    log_scales_at: u32,
    rotations_at: u32,
    opacities_at: u32,
    sh_floats: u32,
    label_channels: u32,
    // Offsets of the moment sections in `moments` (f32s): geometry m and v (the geometry
    // buffer's layout), SH m and v, labels m and v.
    v_geometry_at: u32,
    m_sh_at: u32,
    v_sh_at: u32,
    m_labels_at: u32,
    v_labels_at: u32,
    pad0: u32,
    pad1: u32,
}

const PARAM_FLOATS: u32 = 16u;
const STATS_AT: u32 = 4u;
const STATS_FLOATS: u32 = 4u;

@group(0) @binding(0) var<uniform> u: AdamUniforms;
@group(0) @binding(1) var<storage, read_write> geometry: array<f32>;
@group(0) @binding(2) var<storage, read_write> sh: array<f32>;
@group(0) @binding(3) var<storage, read_write> raw_labels: array<f32>;
@group(0) @binding(4) var<storage, read> param_grads: array<f32>;
@group(0) @binding(5) var<storage, read> v_sh: array<f32>;
@group(0) @binding(6) var<storage, read> v_raw_labels: array<f32>;
@group(0) @binding(7) var<storage, read_write> moments: array<f32>;
// Word 0: the non-finite bits. From word 4, per Gaussian: |v_mean2d| sum (f32 bits), visible
// count, largest radius (f32 bits), frozen (nonzero). Atomic only for word 0's OR; the rest is
// each thread's own and loaded and stored plainly.
@group(0) @binding(8) var<storage, read_write> stats: array<atomic<u32>>;

var<private> bad: u32;

// One value of group `group`: parameter p with gradient g and moments at `m_at` and `v_at`.
fn step_value(group: u32, p: f32, g: f32, m_at: u32, v_at: u32) -> f32 {
    let k = u.groups[group];
    let m = u.beta1 * moments[m_at] + (1.0 - u.beta1) * g;
    let v = u.beta2 * moments[v_at] + (1.0 - u.beta2) * g * g;
    let next = p - k.x * m / (sqrt(v) * k.y + u.eps);
    moments[m_at] = m;
    moments[v_at] = v;
    if !is_finite(g) {
        bad = bad | (1u << group);
    }
    if !is_finite(next) {
        bad = bad | (1u << (8u + group));
    }
    return next;
}

fn on(group: u32) -> bool {
    return u.groups[group].z != 0.0;
}

@compute @workgroup_size(256)
fn adam_step(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let g = (wg.x + wg.y * nwg.x) * 256u + t;
    if g >= u.num_gaussians {
        return;
    }
    let grads = g * PARAM_FLOATS;
    let radius = bitcast<u32>(param_grads[grads + 12u]);
    let s = STATS_AT + STATS_FLOATS * g;
    if radius > 0u {
        let sum = bitcast<f32>(atomicLoad(&stats[s])) + param_grads[grads + 11u];
        atomicStore(&stats[s], bitcast<u32>(sum));
        atomicStore(&stats[s + 1u], atomicLoad(&stats[s + 1u]) + 1u);
        let largest = max(bitcast<f32>(atomicLoad(&stats[s + 2u])), f32(radius));
        atomicStore(&stats[s + 2u], bitcast<u32>(largest));
    }
    if radius == 0u || atomicLoad(&stats[s + 3u]) != 0u {
        return;
    }
    bad = 0u;
    let vg = u.v_geometry_at;
    if on(0u) {
        for (var i = 0u; i < 3u; i = i + 1u) {
            let at = 3u * g + i;
            geometry[at] = step_value(0u, geometry[at], param_grads[grads + i], at, vg + at);
        }
    }
    if on(1u) {
        for (var i = 0u; i < 3u; i = i + 1u) {
            let at = u.log_scales_at + 3u * g + i;
            geometry[at] = step_value(1u, geometry[at], param_grads[grads + 3u + i], at, vg + at);
        }
    }
    if on(2u) {
        for (var i = 0u; i < 4u; i = i + 1u) {
            let at = u.rotations_at + 4u * g + i;
            geometry[at] = step_value(2u, geometry[at], param_grads[grads + 6u + i], at, vg + at);
        }
    }
    if on(3u) {
        let at = u.opacities_at + g;
        geometry[at] = step_value(3u, geometry[at], param_grads[grads + 10u], at, vg + at);
    }
    let k = u.sh_floats;
    for (var i = 0u; i < k; i = i + 1u) {
        let group = select(5u, 4u, i < 3u);
        if on(group) {
            let at = g * k + i;
            sh[at] = step_value(group, sh[at], v_sh[at], u.m_sh_at + at, u.v_sh_at + at);
        }
    }
    if on(6u) {
        for (var i = 0u; i < u.label_channels; i = i + 1u) {
            let at = g * u.label_channels + i;
            raw_labels[at] = step_value(6u, raw_labels[at], v_raw_labels[at], u.m_labels_at + at, u.v_labels_at + at);
        }
    }
    if bad != 0u {
        atomicOr(&stats[0], bad);
    }
}
