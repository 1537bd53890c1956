// The training loss on the GPU and its gradient with respect to the render, the same maths as
// `train::loss::photometric_loss` (L1 + D-SSIM, 3DGS's 11×11 Gaussian window with σ = 1.5 and
// zero 'same' padding, per channel; in a loss region both terms are averaged over the region and
// SSIM compares `m·render + (1-m)·photo`) and `train::loss::label_loss` (weighted binary
// cross-entropy of the blended label channels, clamped probabilities, straight-through gradient).
// The SSIM statistics are planes (map k, channel c: plane 3k + c, `width·height` floats) blurred
// separably by `blur_h` and `blur_v`; its backward blurs three weighted partial maps the same way
// (the window is symmetric, so the blur is its own adjoint). `combine` writes the pixel gradients
// straight into the backward's input (`v_pixels`, stride 5 + label channels). Per workgroup, the
// partial sums of SSIM, L1 and the label loss land in `partials` for the host to add.

struct LossUniforms {
    width: u32,
    height: u32,
    label_channels: u32,
    // Bit k: label channel k is supervised in this view.
    supervised: u32,
    // Planes a blur pass works on.
    planes: u32,
    ssim_lambda: f32,
    rgb_weight: f32,
    label_weight: f32,
    pos_weight: f32,
    eps: f32,
    // 1 / (3 · region mass) (3 · pixels without a region): a_p = m_p · pixel_scale.
    pixel_scale: f32,
    // 1 / (region mass · supervised channels).
    label_scale: f32,
    kernel: array<vec4<f32>, 3>,
}

const RADIUS: i32 = 5;
const C1: f32 = 0.0001;
const C2: f32 = 0.0009;
const PARTIALS: u32 = 3u;

@group(0) @binding(0) var<uniform> u: LossUniforms;

fn weight(i: i32) -> f32 {
    let k = u32(i + RADIUS);
    return u.kernel[k / 4u][k % 4u];
}

// Sums of the workgroup's 256 threads (thread 0 writes them).
var<workgroup> sums: array<vec3<f32>, 256>;

fn reduce_to(t: u32, value: vec3<f32>) -> vec3<f32> {
    sums[t] = value;
    workgroupBarrier();
    for (var stride = 128u; stride > 0u; stride = stride / 2u) {
        if t < stride {
            sums[t] = sums[t] + sums[t + stride];
        }
        workgroupBarrier();
    }
    return sums[0];
}

@group(0) @binding(1) var<storage, read> src_planes: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst_planes: array<f32>;
// The render: RGB composited on the background, alpha.
@group(0) @binding(3) var<storage, read> out_color: array<vec4<f32>>;
// The photo (RGB) and the loss region's weight m_p (1 without a region).
@group(0) @binding(4) var<storage, read> targets: array<vec4<f32>>;
// SSIM statistics: 15 planes (x, y, x², y², xy per channel), then blurred into their means.
@group(0) @binding(5) var<storage, read_write> planes: array<f32>;
// SSIM's weighted partials: 9 planes (d mu_x, d E[x²], d E[xy] per channel).
@group(0) @binding(6) var<storage, read_write> back: array<f32>;
// Per workgroup: SSIM sum, L1 sum, label loss sum.
@group(0) @binding(7) var<storage, read_write> partials: array<f32>;
@group(0) @binding(8) var<storage, read> out_labels: array<f32>;
// Per pixel, bit k: label mask k is set.
@group(0) @binding(9) var<storage, read> label_targets: array<u32>;
@group(0) @binding(10) var<storage, read_write> v_pixels: array<f32>;

fn pixel_index(wg: vec3<u32>, nwg: vec3<u32>, t: u32) -> u32 {
    return (wg.x + wg.y * nwg.x) * 256u + t;
}

// x = m·render + (1-m)·photo (the render where the loss looks, the photo elsewhere).
fn blended(p: u32) -> vec3<f32> {
    let photo = targets[p];
    return photo.w * out_color[p].xyz + (1.0 - photo.w) * photo.xyz;
}

@compute @workgroup_size(256)
fn ssim_prepare(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let n = u.width * u.height;
    let p = pixel_index(wg, nwg, t);
    if p >= n {
        return;
    }
    let x = blended(p);
    let y = targets[p].xyz;
    for (var c = 0u; c < 3u; c = c + 1u) {
        planes[(0u + c) * n + p] = x[c];
        planes[(3u + c) * n + p] = y[c];
        planes[(6u + c) * n + p] = x[c] * x[c];
        planes[(9u + c) * n + p] = y[c] * y[c];
        planes[(12u + c) * n + p] = x[c] * y[c];
    }
}

// One thread per (plane, pixel): the 11-tap window along the row, zero beyond the image.
@compute @workgroup_size(256)
fn blur_h(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let n = u.width * u.height;
    let i = pixel_index(wg, nwg, t);
    if i >= n * u.planes {
        return;
    }
    let plane = i / n;
    let p = i % n;
    let x = i32(p % u.width);
    let row = plane * n + (p - p % u.width);
    var sum = 0.0;
    for (var k = -RADIUS; k <= RADIUS; k = k + 1) {
        let xx = x + k;
        if xx >= 0 && xx < i32(u.width) {
            sum += weight(k) * src_planes[row + u32(xx)];
        }
    }
    dst_planes[i] = sum;
}

// The same down the column.
@compute @workgroup_size(256)
fn blur_v(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let n = u.width * u.height;
    let i = pixel_index(wg, nwg, t);
    if i >= n * u.planes {
        return;
    }
    let plane = i / n;
    let p = i % n;
    let x = p % u.width;
    let y = i32(p / u.width);
    var sum = 0.0;
    for (var k = -RADIUS; k <= RADIUS; k = k + 1) {
        let yy = y + k;
        if yy >= 0 && yy < i32(u.height) {
            sum += weight(k) * src_planes[plane * n + u32(yy) * u.width + x];
        }
    }
    dst_planes[i] = sum;
}

// Per pixel: SSIM from the blurred statistics, weighted by a_p, and its partials with respect
// to mu_x, E[x²] and E[xy] (as `ssim::stats_row`), written into `back` for the blur.
@compute @workgroup_size(256)
fn ssim_maps(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let n = u.width * u.height;
    let p = pixel_index(wg, nwg, t);
    var ssim_sum = 0.0;
    if p < n {
        let a_p = targets[p].w * u.pixel_scale;
        for (var c = 0u; c < 3u; c = c + 1u) {
            let mx = planes[(0u + c) * n + p];
            let my = planes[(3u + c) * n + p];
            let var_x = planes[(6u + c) * n + p] - mx * mx;
            let var_y = planes[(9u + c) * n + p] - my * my;
            let cov = planes[(12u + c) * n + p] - mx * my;
            let a1 = 2.0 * mx * my + C1;
            let a2 = 2.0 * cov + C2;
            let b1 = mx * mx + my * my + C1;
            let b2 = var_x + var_y + C2;
            let inv = 1.0 / (b1 * b2);
            let ssim = a1 * a2 * inv;
            ssim_sum += a_p * ssim;
            let d_mu = 2.0 * my * a2 * inv - 2.0 * mx * ssim / b1;
            let d_var = -ssim / b2;
            let d_cov = 2.0 * a1 * inv;
            back[(0u + c) * n + p] = a_p * (d_mu - 2.0 * mx * d_var - my * d_cov);
            back[(3u + c) * n + p] = a_p * d_var;
            back[(6u + c) * n + p] = a_p * d_cov;
        }
    }
    let total = reduce_to(t, vec3<f32>(ssim_sum, 0.0, 0.0));
    if t == 0u {
        partials[(wg.x + wg.y * nwg.x) * PARTIALS] = total.x;
    }
}

// Per pixel: dL/d(render) from L1, the blurred SSIM partials (dS/dx = B0 + 2x·B1 + y·B2,
// through the blend: · m_p) and the label cross-entropy, into the backward's pixel gradients.
@compute @workgroup_size(256)
fn combine(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let n = u.width * u.height;
    let p = pixel_index(wg, nwg, t);
    let lcs = u.label_channels;
    var l1_sum = 0.0;
    var label_sum = 0.0;
    if p < n {
        let photo = targets[p];
        let m = photo.w;
        let a_p = m * u.pixel_scale;
        let render = out_color[p].xyz;
        let x = blended(p);
        let at = p * (5u + lcs);
        let lambda = u.ssim_lambda;
        for (var c = 0u; c < 3u; c = c + 1u) {
            let d = render[c] - photo[c];
            l1_sum += a_p * abs(d);
            // d|d|/dd = sign(d), 0 at 0 (torch).
            let v_ssim = back[(0u + c) * n + p] + 2.0 * x[c] * back[(3u + c) * n + p]
                + photo[c] * back[(6u + c) * n + p];
            v_pixels[at + c] = u.rgb_weight * ((1.0 - lambda) * a_p * sign(d) - lambda * m * v_ssim);
        }
        v_pixels[at + 3u] = 0.0;
        v_pixels[at + 4u] = 0.0;
        let bits = label_targets[p];
        for (var k = 0u; k < lcs; k = k + 1u) {
            var v = 0.0;
            if m != 0.0 && (u.supervised & (1u << k)) != 0u {
                let q = clamp(out_labels[p * lcs + k], u.eps, 1.0 - u.eps);
                let scale = m * u.label_scale;
                if (bits & (1u << k)) != 0u {
                    label_sum -= scale * u.pos_weight * log(q);
                    v = -scale * u.pos_weight / q;
                } else {
                    label_sum -= scale * log(1.0 - q);
                    v = scale / (1.0 - q);
                }
            }
            v_pixels[at + 5u + k] = u.label_weight * v;
        }
    }
    let total = reduce_to(t, vec3<f32>(0.0, l1_sum, label_sum));
    if t == 0u {
        let w = (wg.x + wg.y * nwg.x) * PARTIALS;
        partials[w + 1u] = total.y;
        partials[w + 2u] = total.z;
    }
}
