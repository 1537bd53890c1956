// Stage 6, tile rasterizer: one 16×16 workgroup per tile, one thread per pixel. The tile's
// depth-ordered Gaussians are loaded 256 at a time into shared memory (one per thread), then
// every pixel blends them front to back exactly as the CPU reference: alpha = min(alpha_max, o·e^-σ),
// skip alpha < 1/255, stop before transmittance would fall to 1e-4. The loop ends early once
// every pixel of the tile is done. Writes colour (composited on the background), alpha, depth
// (Σ z·α·T, not normalised), label channels (Σ p·α·T), an Rgba8Unorm texture for display, and
// per pixel what the backward replays from: the final transmittance and how many of the tile's
// Gaussians it went through to its last blended one.

const BATCH: u32 = 256u;
const ALPHA_MIN: f32 = 0.00392156862745098; // 1/255
const T_MIN: f32 = 1e-4;

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var<storage, read> ranges: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read> isect_gids: array<u32>;
@group(0) @binding(3) var<storage, read> projected: array<ProjectedSplat>;
@group(0) @binding(4) var<storage, read> labels: array<f32>;
@group(0) @binding(5) var<storage, read_write> out_color: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> out_depth: array<f32>;
@group(0) @binding(7) var<storage, read_write> out_labels: array<f32>;
@group(0) @binding(8) var out_texture: texture_storage_2d<rgba8unorm, write>;
// (bits of T_final, 1 + index in the tile's range of the last blended Gaussian; 0: none).
@group(0) @binding(9) var<storage, read_write> out_state: array<vec2<u32>>;

// x, y, opacity, depth | conic a, b, c, unused | r, g, b, unused | gaussian id
var<workgroup> batch_xy_opacity: array<vec4<f32>, BATCH>;
var<workgroup> batch_conic: array<vec4<f32>, BATCH>;
var<workgroup> batch_color: array<vec4<f32>, BATCH>;
var<workgroup> batch_gid: array<u32, BATCH>;
var<workgroup> done_count: atomic<u32>;
var<workgroup> done_snapshot: u32;

@compute @workgroup_size(16, 16)
fn rasterize(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let tile = wg.y * u.tile_bounds.x + wg.x;
    let px = wg.x * TILE_WIDTH + lid.x;
    let py = wg.y * TILE_WIDTH + lid.y;
    let inside = px < u.img_size.x && py < u.img_size.y;
    // Pixel centres at +0.5 (gsplat convention).
    let pixel = vec2<f32>(f32(px) + 0.5, f32(py) + 0.5);
    let range = ranges[tile];
    let total = range.y - range.x;
    let num_batches = (total + BATCH - 1u) / BATCH;
    let lc = min(u.label_channels, MAX_LABELS);

    var transmittance = 1.0;
    var color = vec3<f32>(0.0);
    var depth = 0.0;
    var acc_labels: array<f32, MAX_LABELS>;
    for (var k = 0u; k < MAX_LABELS; k = k + 1u) {
        acc_labels[k] = 0.0;
    }
    var done = !inside;
    var last = 0u;
    if t == 0u {
        atomicStore(&done_count, 0u);
    }
    workgroupBarrier();
    if done {
        atomicAdd(&done_count, 1u);
    }

    for (var b = 0u; b < num_batches; b = b + 1u) {
        // Everyone has finished the previous batch (and counted itself if done).
        workgroupBarrier();
        if t == 0u {
            done_snapshot = atomicLoad(&done_count);
        }
        if workgroupUniformLoad(&done_snapshot) >= BATCH {
            break;
        }
        let idx = range.x + b * BATCH + t;
        if idx < range.y {
            let gid = isect_gids[idx];
            let p = projected[gid];
            batch_xy_opacity[t] = vec4<f32>(p.xy, p.opacity, p.depth);
            batch_conic[t] = vec4<f32>(p.conic, 0.0);
            batch_gid[t] = gid;
            batch_color[t] = vec4<f32>(p.color, 0.0);
        }
        workgroupBarrier();
        if !done {
            let in_batch = min(BATCH, total - b * BATCH);
            for (var j = 0u; j < in_batch; j = j + 1u) {
                let xyo = batch_xy_opacity[j];
                let conic = batch_conic[j];
                let d = xyo.xy - pixel;
                let sigma = 0.5 * (conic.x * d.x * d.x + conic.z * d.y * d.y) + conic.y * d.x * d.y;
                let alpha = min(u.alpha_max, xyo.z * exp(-sigma));
                if sigma < 0.0 || alpha < ALPHA_MIN {
                    continue;
                }
                let next_t = transmittance * (1.0 - alpha);
                if next_t <= T_MIN {
                    done = true;
                    break;
                }
                let weight = alpha * transmittance;
                color += batch_color[j].xyz * weight;
                depth += xyo.w * weight;
                let gid = batch_gid[j];
                for (var k = 0u; k < lc; k = k + 1u) {
                    acc_labels[k] += labels[gid * u.label_channels + k] * weight;
                }
                transmittance = next_t;
                last = b * BATCH + j + 1u;
            }
            if done {
                atomicAdd(&done_count, 1u);
            }
        }
    }

    if inside {
        let pix = py * u.img_size.x + px;
        let final_color = color + transmittance * u.background.xyz;
        out_color[pix] = vec4<f32>(final_color, 1.0 - transmittance);
        out_depth[pix] = depth;
        out_state[pix] = vec2<u32>(bitcast<u32>(transmittance), last);
        for (var k = 0u; k < lc; k = k + 1u) {
            out_labels[pix * u.label_channels + k] = acc_labels[k];
        }
        textureStore(out_texture, vec2<i32>(i32(px), i32(py)), vec4<f32>(clamp(final_color, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0 - transmittance));
    }
}
