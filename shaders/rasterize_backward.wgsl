// Backward of stage 6 (rasterize), gsplat's `rasterize_to_pixels_bwd`: one 16×16 workgroup per
// tile, one thread per pixel. Each pixel starts from what the forward left it (final
// transmittance, how many of the tile's Gaussians it went through) and walks the tile's
// Gaussians back to front, batch by batch through shared memory, recovering T_i = T_{i+1} / (1 - α_i)
// and the colour/depth/label worth of what lies behind, exactly as `raster::reference_backward`:
//   dL/dα_i = T_i s_i - (Σ_{j>i} w_j s_j + T_f (background · g_rgb - g_alpha)) / (1 - α_i).
// Per Gaussian the pixel's share of the screen-space gradients is added into `screen_grads`
// (stride 10 + label channels: mean2d xy, conic abc, colour rgb, opacity, depth, labels) by
// `add_grad`, which the host supplies: a float atomic add where the device has one, otherwise a
// compare-and-swap loop on the bits (WGSL core has no float atomics).

const BATCH: u32 = 256u;
const ALPHA_MIN: f32 = 0.00392156862745098; // 1/255, as the forward
const SCREEN_FLOATS: u32 = 10u;

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var<storage, read> ranges: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read> isect_gids: array<u32>;
@group(0) @binding(3) var<storage, read> projected: array<ProjectedSplat>;
@group(0) @binding(4) var<storage, read> labels: array<f32>;
@group(0) @binding(5) var<storage, read> out_state: array<vec2<u32>>;
// Per pixel, stride 5 + label channels: dL/d(r, g, b, alpha, depth, labels...).
@group(0) @binding(6) var<storage, read> v_pixels: array<f32>;

var<workgroup> batch_xy_opacity: array<vec4<f32>, BATCH>;
var<workgroup> batch_conic: array<vec4<f32>, BATCH>;
var<workgroup> batch_color: array<vec4<f32>, BATCH>;
var<workgroup> batch_gid: array<u32, BATCH>;
var<workgroup> max_count: atomic<u32>;
var<workgroup> max_count_snapshot: u32;

@compute @workgroup_size(16, 16)
fn rasterize_backward(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let tile = wg.y * u.tile_bounds.x + wg.x;
    let px = wg.x * TILE_WIDTH + lid.x;
    let py = wg.y * TILE_WIDTH + lid.y;
    let inside = px < u.img_size.x && py < u.img_size.y;
    let pixel = vec2<f32>(f32(px) + 0.5, f32(py) + 0.5);
    let range = ranges[tile];
    let lcs = u.label_channels;
    let lc = min(lcs, MAX_LABELS);
    let stride = SCREEN_FLOATS + lcs;

    var t_final = 1.0;
    var count = 0u;
    var g_rgb = vec3<f32>(0.0);
    var g_alpha = 0.0;
    var g_depth = 0.0;
    var g_labels: array<f32, MAX_LABELS>;
    for (var k = 0u; k < MAX_LABELS; k = k + 1u) {
        g_labels[k] = 0.0;
    }
    if inside {
        let pix = py * u.img_size.x + px;
        let state = out_state[pix];
        t_final = bitcast<f32>(state.x);
        count = state.y;
        let at = pix * (5u + lcs);
        g_rgb = vec3<f32>(v_pixels[at], v_pixels[at + 1u], v_pixels[at + 2u]);
        g_alpha = v_pixels[at + 3u];
        g_depth = v_pixels[at + 4u];
        for (var k = 0u; k < lc; k = k + 1u) {
            g_labels[k] = v_pixels[at + 5u + k];
        }
    }
    if t == 0u {
        atomicStore(&max_count, 0u);
    }
    workgroupBarrier();
    atomicMax(&max_count, count);
    workgroupBarrier();
    if t == 0u {
        max_count_snapshot = atomicLoad(&max_count);
    }
    // Only the Gaussians up to the tile's deepest last-blended one matter.
    let tile_count = min(workgroupUniformLoad(&max_count_snapshot), range.y - range.x);

    var transmittance = t_final;
    let final_term = t_final * (dot(u.background.xyz, g_rgb) - g_alpha);
    var behind = 0.0;
    let num_batches = (tile_count + BATCH - 1u) / BATCH;
    for (var b = 0u; b < num_batches; b = b + 1u) {
        // This batch holds range indices [end - in_batch, end), loaded back to front.
        let end = tile_count - b * BATCH;
        let in_batch = min(BATCH, end);
        workgroupBarrier();
        if t < in_batch {
            let gid = isect_gids[range.x + end - 1u - t];
            let p = projected[gid];
            batch_xy_opacity[t] = vec4<f32>(p.xy, p.opacity, p.depth);
            batch_conic[t] = vec4<f32>(p.conic, 0.0);
            batch_color[t] = vec4<f32>(p.color, 0.0);
            batch_gid[t] = gid;
        }
        workgroupBarrier();
        for (var j = 0u; j < in_batch; j = j + 1u) {
            // Index of this Gaussian in the tile's range; the pixel blended only those below count.
            let index = end - 1u - j;
            if index >= count {
                continue;
            }
            let xyo = batch_xy_opacity[j];
            let conic = batch_conic[j].xyz;
            let d = xyo.xy - pixel;
            let sigma = 0.5 * (conic.x * d.x * d.x + conic.z * d.y * d.y) + conic.y * d.x * d.y;
            let falloff = exp(-sigma);
            let raw_alpha = xyo.z * falloff;
            let alpha = min(u.alpha_max, raw_alpha);
            if sigma < 0.0 || alpha < ALPHA_MIN {
                continue;
            }
            transmittance = transmittance / (1.0 - alpha);
            let gid = batch_gid[j];
            let color = batch_color[j].xyz;
            var label_worth = 0.0;
            for (var k = 0u; k < lc; k = k + 1u) {
                label_worth += labels[gid * lcs + k] * g_labels[k];
            }
            let worth = dot(color, g_rgb) + xyo.w * g_depth + label_worth;
            let weight = alpha * transmittance;
            let v_alpha = transmittance * worth - (behind + final_term) / (1.0 - alpha);
            behind += weight * worth;

            let base = gid * stride;
            add_grad(base + 5u, weight * g_rgb.x);
            add_grad(base + 6u, weight * g_rgb.y);
            add_grad(base + 7u, weight * g_rgb.z);
            add_grad(base + 9u, weight * g_depth);
            for (var k = 0u; k < lc; k = k + 1u) {
                add_grad(base + SCREEN_FLOATS + k, weight * g_labels[k]);
            }
            // A clamped alpha is the constant alpha_max: nothing reaches opacity or power.
            if raw_alpha <= u.alpha_max {
                let v_sigma = -raw_alpha * v_alpha;
                add_grad(base + 8u, falloff * v_alpha);
                add_grad(base + 2u, 0.5 * v_sigma * d.x * d.x);
                add_grad(base + 3u, v_sigma * d.x * d.y);
                add_grad(base + 4u, 0.5 * v_sigma * d.y * d.y);
                add_grad(base + 0u, v_sigma * (conic.x * d.x + conic.y * d.y));
                add_grad(base + 1u, v_sigma * (conic.y * d.x + conic.z * d.y));
            }
        }
    }
}
