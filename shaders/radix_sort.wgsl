// Stable LSD radix sort of (u32 key, u32 value) pairs, 4 bits per pass, 1024-element blocks
// (256 threads × 4 consecutive elements). Per pass: `histogram` counts digits per block into a
// digit-major table, prefix_sum.wgsl scans that table, `scatter` writes each element to
// scanned[digit][block] + its rank among equal digits before it in the block. Ranks come from a
// workgroup scan over thread-ordered counts, so equal keys keep their input order (stable): the
// tile sort relies on this to keep the depth order inside each tile.
// The element count lives on the GPU: `setup` clamps it to the capacity and writes the sizes
// and the indirect dispatch arguments, so there is no read-back.

const WG: u32 = 256u;
const PER_THREAD: u32 = 4u;
const BLOCK: u32 = 1024u;
const BINS: u32 = 16u;
const MAX_GROUPS_X: u32 = 65535u;
// Words between two scan levels' lengths (prefix_sum.rs LEN_STRIDE_WORDS).
const SCAN_LEN_STRIDE: u32 = 64u;
const SCAN_BLOCK: u32 = 512u;

struct Config {
    capacity: u32,
    scan_levels: u32,
}

struct Sizes {
    n: u32,
    num_blocks: u32,
}

struct Pass {
    shift: u32,
}

// --- setup (one thread) ---
@group(0) @binding(0) var<storage, read> count_in: array<u32>;
@group(0) @binding(1) var<storage, read> config: Config;
@group(0) @binding(2) var<storage, read_write> sizes_out: Sizes;
@group(0) @binding(3) var<storage, read_write> dispatch_args: array<u32>;
@group(0) @binding(4) var<storage, read_write> scan_len: array<u32>;

@compute @workgroup_size(1)
fn setup() {
    let n = min(count_in[0], config.capacity);
    let blocks = (n + BLOCK - 1u) / BLOCK;
    sizes_out.n = n;
    sizes_out.num_blocks = blocks;
    // Same 2D split as kernel::grid on the host.
    if blocks <= MAX_GROUPS_X {
        dispatch_args[0] = blocks;
        dispatch_args[1] = 1u;
    } else {
        dispatch_args[0] = MAX_GROUPS_X;
        dispatch_args[1] = (blocks + MAX_GROUPS_X - 1u) / MAX_GROUPS_X;
    }
    dispatch_args[2] = 1u;
    var level_n = blocks * BINS;
    for (var l = 0u; l < config.scan_levels; l = l + 1u) {
        scan_len[l * SCAN_LEN_STRIDE] = level_n;
        level_n = (level_n + SCAN_BLOCK - 1u) / SCAN_BLOCK;
    }
}

// --- histogram and scatter ---
@group(0) @binding(5) var<storage, read> sizes: Sizes;
@group(0) @binding(6) var<storage, read> pass_info: Pass;
@group(0) @binding(7) var<storage, read> keys_in: array<u32>;
@group(0) @binding(8) var<storage, read> values_in: array<u32>;
@group(0) @binding(9) var<storage, read_write> hist: array<u32>;
@group(0) @binding(10) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(11) var<storage, read_write> values_out: array<u32>;
@group(0) @binding(12) var<storage, read> hist_scanned: array<u32>;

var<workgroup> digit_counts: array<atomic<u32>, BINS>;
// Per thread, 16 digit counts packed as 16-bit pairs (a block has at most 1024 elements).
var<workgroup> packed_prefix: array<array<u32, 8>, WG>;

@compute @workgroup_size(256)
fn histogram(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let block = wg.x + wg.y * nwg.x;
    if t < BINS {
        atomicStore(&digit_counts[t], 0u);
    }
    workgroupBarrier();
    let n = sizes.n;
    let shift = pass_info.shift;
    for (var j = 0u; j < PER_THREAD; j = j + 1u) {
        let i = block * BLOCK + t * PER_THREAD + j;
        if i < n {
            atomicAdd(&digit_counts[(keys_in[i] >> shift) & 15u], 1u);
        }
    }
    workgroupBarrier();
    if t < BINS && block < sizes.num_blocks {
        hist[t * sizes.num_blocks + block] = atomicLoad(&digit_counts[t]);
    }
}

@compute @workgroup_size(256)
fn scatter(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let block = wg.x + wg.y * nwg.x;
    let n = sizes.n;
    let shift = pass_info.shift;
    var keys: array<u32, PER_THREAD>;
    var values: array<u32, PER_THREAD>;
    var own: array<u32, 8>;
    for (var w = 0u; w < 8u; w = w + 1u) {
        own[w] = 0u;
    }
    for (var j = 0u; j < PER_THREAD; j = j + 1u) {
        let i = block * BLOCK + t * PER_THREAD + j;
        if i < n {
            keys[j] = keys_in[i];
            values[j] = values_in[i];
            let d = (keys[j] >> shift) & 15u;
            own[d >> 1u] = own[d >> 1u] + (1u << ((d & 1u) * 16u));
        }
    }
    packed_prefix[t] = own;
    workgroupBarrier();
    // Inclusive Hillis-Steele scan of the packed counts across the 256 threads.
    for (var offset = 1u; offset < WG; offset = offset << 1u) {
        var add: array<u32, 8>;
        for (var w = 0u; w < 8u; w = w + 1u) {
            add[w] = 0u;
        }
        if t >= offset {
            add = packed_prefix[t - offset];
        }
        workgroupBarrier();
        if t >= offset {
            for (var w = 0u; w < 8u; w = w + 1u) {
                packed_prefix[t][w] = packed_prefix[t][w] + add[w];
            }
        }
        workgroupBarrier();
    }
    let num_blocks = sizes.num_blocks;
    for (var j = 0u; j < PER_THREAD; j = j + 1u) {
        let i = block * BLOCK + t * PER_THREAD + j;
        if i < n {
            let d = (keys[j] >> shift) & 15u;
            // Earlier threads' count of digit d (inclusive minus own never borrows across fields).
            let field = (d & 1u) * 16u;
            var rank = ((packed_prefix[t][d >> 1u] - own[d >> 1u]) >> field) & 0xffffu;
            for (var k = 0u; k < j; k = k + 1u) {
                if ((keys[k] >> shift) & 15u) == d {
                    rank = rank + 1u;
                }
            }
            let dst = hist_scanned[d * num_blocks + block] + rank;
            keys_out[dst] = keys[j];
            values_out[dst] = values[j];
        }
    }
}
