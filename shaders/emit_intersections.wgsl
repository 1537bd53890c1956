// Stage 3, tile/Gaussian intersections. Gaussians arrive sorted by depth (`sorted_gids`);
// `gather_counts` lays their tile counts out in that order, prefix_sum.wgsl turns them into
// write offsets, and `emit` writes one (tile id, gaussian id) pair per touched tile. Because the
// pairs are written in depth order and the tile sort is stable, each tile's list stays
// front-to-back. Pairs past `isect_capacity` are dropped (the host grows the buffers for the
// next frame from the unclamped total in `isect_count`; no read-back stalls the frame).

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var<storage, read> projected: array<ProjectedSplat>;
@group(0) @binding(2) var<storage, read> sorted_gids: array<u32>;
@group(0) @binding(3) var<storage, read_write> offsets: array<u32>;
@group(0) @binding(4) var<storage, read_write> tile_keys: array<u32>;
@group(0) @binding(5) var<storage, read_write> isect_gids: array<u32>;
@group(0) @binding(6) var<storage, read_write> isect_count: array<u32>;

@compute @workgroup_size(256)
fn gather_counts(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let i = (wg.x + wg.y * nwg.x) * 256u + t;
    if i < u.num_gaussians {
        offsets[i] = projected[sorted_gids[i]].tiles;
    }
}

@compute @workgroup_size(256)
fn emit(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let i = (wg.x + wg.y * nwg.x) * 256u + t;
    if i >= u.num_gaussians {
        return;
    }
    let gid = sorted_gids[i];
    let p = projected[gid];
    let start = offsets[i];
    if i == u.num_gaussians - 1u {
        isect_count[0] = start + p.tiles;
    }
    if p.tiles == 0u {
        return;
    }
    let x0 = p.rect_x & 0xffffu;
    let x1 = p.rect_x >> 16u;
    let y0 = p.rect_y & 0xffffu;
    let y1 = p.rect_y >> 16u;
    var at = start;
    for (var ty = y0; ty < y1; ty = ty + 1u) {
        for (var tx = x0; tx < x1; tx = tx + 1u) {
            if at < u.isect_capacity {
                tile_keys[at] = ty * u.tile_bounds.x + tx;
                isect_gids[at] = gid;
            }
            at = at + 1u;
        }
    }
}
