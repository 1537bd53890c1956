// Stage 5, tile ranges: after the stable tile sort, each tile's intersections are contiguous;
// `tile_ranges` finds every run's [start, end) by comparing neighbours (4 per thread), and
// `clear_ranges` first resets tiles that have none to (0, 0). The count comes from the sort's
// GPU-side sizes (clamped to the capacity), dispatched indirectly.

struct Sizes {
    n: u32,
    num_blocks: u32,
}

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var<storage, read> sizes: Sizes;
@group(0) @binding(2) var<storage, read> tile_keys: array<u32>;
@group(0) @binding(3) var<storage, read_write> ranges: array<vec2<u32>>;

@compute @workgroup_size(256)
fn clear_ranges(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let tile = (wg.x + wg.y * nwg.x) * 256u + t;
    if tile < u.tile_bounds.x * u.tile_bounds.y {
        ranges[tile] = vec2<u32>(0u, 0u);
    }
}

@compute @workgroup_size(256)
fn tile_ranges(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let n = sizes.n;
    let first = ((wg.x + wg.y * nwg.x) * 256u + t) * 4u;
    for (var j = 0u; j < 4u; j = j + 1u) {
        let i = first + j;
        if i < n {
            let tile = tile_keys[i];
            if i == 0u || tile_keys[i - 1u] != tile {
                ranges[tile].x = i;
            }
            if i + 1u == n || tile_keys[i + 1u] != tile {
                ranges[tile].y = i + 1u;
            }
        }
    }
}
