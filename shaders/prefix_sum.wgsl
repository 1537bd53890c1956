// Exclusive prefix sum of u32, in place, one 512-element block per workgroup (256 threads, two
// elements each). A multi-level scan runs `scan_blocks` on each level (block totals go to the
// next level), then `add_offsets` top-down. The element count of a level is read from `len[0]`
// (written by the host, or by another kernel when the count only exists on the GPU), so
// workgroups past the end do nothing: barriers stay in uniform control flow regardless.

const WG: u32 = 256u;
const BLOCK: u32 = 512u;

@group(0) @binding(0) var<storage, read> len: array<u32>;
@group(0) @binding(1) var<storage, read_write> data: array<u32>;
@group(0) @binding(2) var<storage, read_write> block_sums: array<u32>;

var<workgroup> partial: array<u32, WG>;

@compute @workgroup_size(256)
fn scan_blocks(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let block = wg.x + wg.y * nwg.x;
    let n = len[0];
    let i0 = block * BLOCK + 2u * t;
    var a = 0u;
    var b = 0u;
    if i0 < n {
        a = data[i0];
    }
    if i0 + 1u < n {
        b = data[i0 + 1u];
    }
    let own = a + b;
    partial[t] = own;
    workgroupBarrier();
    // Hillis-Steele inclusive scan of the 256 pair sums: 8 steps, reads and writes fenced apart.
    for (var offset = 1u; offset < WG; offset = offset << 1u) {
        var v = partial[t];
        if t >= offset {
            v = v + partial[t - offset];
        }
        workgroupBarrier();
        partial[t] = v;
        workgroupBarrier();
    }
    let exclusive = partial[t] - own;
    if i0 < n {
        data[i0] = exclusive;
    }
    if i0 + 1u < n {
        data[i0 + 1u] = exclusive + a;
    }
    if t == WG - 1u && block * BLOCK < n {
        block_sums[block] = partial[t];
    }
}

@compute @workgroup_size(256)
fn add_offsets(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let block = wg.x + wg.y * nwg.x;
    let n = len[0];
    if block == 0u || block * BLOCK >= n {
        return;
    }
    let add = block_sums[block];
    let i0 = block * BLOCK + 2u * t;
    if i0 < n {
        data[i0] = data[i0] + add;
    }
    if i0 + 1u < n {
        data[i0 + 1u] = data[i0 + 1u] + add;
    }
}
