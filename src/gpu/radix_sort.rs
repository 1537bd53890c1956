//! Host side of `shaders/radix_sort.wgsl`: a stable key/value radix sort whose element count
//! stays on the GPU (read from a buffer, clamped to the capacity, dispatched indirectly), so a
//! frame can sort a number of intersections the CPU never learns.

use wgpu::util::DeviceExt;

use super::kernel::{self, Bind};
use super::prefix_sum::{PrefixSum, ScanLen};

/// Elements per block, as in the shader.
pub const BLOCK: u32 = 1024;
/// Bits per pass (16 digits).
pub const BITS_PER_PASS: u32 = 4;
const MAX_PASSES: u32 = 8;
const SLOT: u64 = 256;

const SHADER: &str = include_str!("../../shaders/radix_sort.wgsl");

/// Which pair of buffers holds the sorted result.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SortedIn {
    /// The caller's `keys`/`values` buffers (an even number of passes).
    Input,
    /// The sorter's own scratch buffers ([`RadixSort::scratch_keys`], [`RadixSort::scratch_values`]).
    Scratch,
}

pub struct RadixSort {
    setup: wgpu::ComputePipeline,
    histogram: wgpu::ComputePipeline,
    scatter: wgpu::ComputePipeline,
    capacity: u32,
    scan: PrefixSum,
    hist: wgpu::Buffer,
    keys_b: wgpu::Buffer,
    values_b: wgpu::Buffer,
    config: wgpu::Buffer,
    sizes: wgpu::Buffer,
    dispatch_args: wgpu::Buffer,
    pass_info: wgpu::Buffer,
}

/// Number of 4-bit passes needed for keys below `1 << bits`.
pub fn passes_for_bits(bits: u32) -> u32 {
    bits.div_ceil(BITS_PER_PASS).clamp(1, MAX_PASSES)
}

/// Bits needed to hold every value in `0..=max_key`.
pub fn bits_for(max_key: u32) -> u32 {
    32 - max_key.leading_zeros()
}

impl RadixSort {
    /// A sorter for up to `capacity` pairs.
    pub fn new(device: &wgpu::Device, capacity: u32) -> RadixSort {
        let pipelines = kernel::pipelines(
            device,
            "radix_sort",
            SHADER,
            ["setup", "histogram", "scatter"],
        );
        Self::with_pipelines(device, pipelines, PrefixSum::new(device, 1), capacity)
    }

    /// The same sorter with room for `capacity` pairs: new buffers, the same compiled pipelines.
    pub fn resized(&self, device: &wgpu::Device, capacity: u32) -> RadixSort {
        let pipelines = [
            self.setup.clone(),
            self.histogram.clone(),
            self.scatter.clone(),
        ];
        Self::with_pipelines(device, pipelines, self.scan.resized(device, 1), capacity)
    }

    fn with_pipelines(
        device: &wgpu::Device,
        [setup, histogram, scatter]: [wgpu::ComputePipeline; 3],
        scan: PrefixSum,
        capacity: u32,
    ) -> RadixSort {
        let capacity = capacity.max(1);
        let max_blocks = capacity.div_ceil(BLOCK);
        let hist_len = max_blocks * 16;
        let scan = scan.resized(device, hist_len);
        let hist = kernel::storage(
            device,
            "radix_sort.hist",
            hist_len as u64 * 4,
            wgpu::BufferUsages::empty(),
        );
        let none = wgpu::BufferUsages::empty();
        let keys_b = kernel::storage(device, "radix_sort.keys_b", capacity as u64 * 4, none);
        let values_b = kernel::storage(device, "radix_sort.values_b", capacity as u64 * 4, none);
        let config = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("radix_sort.config"),
            contents: bytemuck::cast_slice(&[capacity, scan.levels(), 0, 0]),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let sizes = kernel::storage(device, "radix_sort.sizes", 16, none);
        let dispatch_args = kernel::storage(
            device,
            "radix_sort.dispatch",
            16,
            wgpu::BufferUsages::INDIRECT,
        );
        let mut slots = vec![0u32; (MAX_PASSES as usize) * (SLOT as usize / 4)];
        for p in 0..MAX_PASSES as usize {
            slots[p * SLOT as usize / 4] = p as u32 * BITS_PER_PASS;
        }
        let pass_info = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("radix_sort.passes"),
            contents: bytemuck::cast_slice(&slots),
            usage: wgpu::BufferUsages::STORAGE,
        });
        RadixSort {
            setup,
            histogram,
            scatter,
            capacity,
            scan,
            hist,
            keys_b,
            values_b,
            config,
            sizes,
            dispatch_args,
            pass_info,
        }
    }

    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Where the result of a sort by `bits` bits ends up (known before encoding).
    pub fn result_location(bits: u32) -> SortedIn {
        if passes_for_bits(bits).is_multiple_of(2) {
            SortedIn::Input
        } else {
            SortedIn::Scratch
        }
    }

    /// GPU-side `{ n, num_blocks }` of the last encoded sort (n clamped to the capacity).
    pub fn sizes(&self) -> &wgpu::Buffer {
        &self.sizes
    }

    /// Indirect dispatch arguments covering `n` in blocks of [`BLOCK`].
    pub fn dispatch_args(&self) -> &wgpu::Buffer {
        &self.dispatch_args
    }

    pub fn scratch_keys(&self) -> &wgpu::Buffer {
        &self.keys_b
    }

    pub fn scratch_values(&self) -> &wgpu::Buffer {
        &self.values_b
    }

    /// Encodes a sort of the first `count[0]` pairs (clamped to the capacity) of `keys`/`values`
    /// by their low `bits` bits. `count` is a buffer whose first word is the element count, as
    /// left by an earlier kernel or by `queue.write_buffer`. Returns where the result is.
    pub fn encode(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu::ComputePass<'_>,
        keys: &wgpu::Buffer,
        values: &wgpu::Buffer,
        count: &wgpu::Buffer,
        bits: u32,
    ) -> SortedIn {
        let setup = kernel::bind_group(
            device,
            &self.setup,
            &[
                (0, Bind::Range(count, 0, 4)),
                (1, Bind::Buffer(&self.config)),
                (2, Bind::Buffer(&self.sizes)),
                (3, Bind::Buffer(&self.dispatch_args)),
                (4, Bind::Buffer(self.scan.len_buffer())),
            ],
        );
        pass.set_pipeline(&self.setup);
        pass.set_bind_group(0, &setup, &[]);
        pass.dispatch_workgroups(1, 1, 1);

        let passes = passes_for_bits(bits);
        for p in 0..passes {
            let (k_in, v_in, k_out, v_out) = if p % 2 == 0 {
                (keys, values, &self.keys_b, &self.values_b)
            } else {
                (&self.keys_b, &self.values_b, keys, values)
            };
            let info = Bind::Range(&self.pass_info, p as u64 * SLOT, 4);
            let hist_group = kernel::bind_group(
                device,
                &self.histogram,
                &[
                    (5, Bind::Buffer(&self.sizes)),
                    (6, info),
                    (7, Bind::Buffer(k_in)),
                    (9, Bind::Buffer(&self.hist)),
                ],
            );
            let scatter_group = kernel::bind_group(
                device,
                &self.scatter,
                &[
                    (5, Bind::Buffer(&self.sizes)),
                    (6, Bind::Range(&self.pass_info, p as u64 * SLOT, 4)),
                    (7, Bind::Buffer(k_in)),
                    (8, Bind::Buffer(v_in)),
                    (10, Bind::Buffer(k_out)),
                    (11, Bind::Buffer(v_out)),
                    (12, Bind::Buffer(&self.hist)),
                ],
            );
            pass.set_pipeline(&self.histogram);
            pass.set_bind_group(0, &hist_group, &[]);
            pass.dispatch_workgroups_indirect(&self.dispatch_args, 0);
            self.scan.encode(device, pass, &self.hist, ScanLen::Device);
            pass.set_pipeline(&self.scatter);
            pass.set_bind_group(0, &scatter_group, &[]);
            pass.dispatch_workgroups_indirect(&self.dispatch_args, 0);
        }
        Self::result_location(bits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::{GpuContext, readback};

    fn sort_on_gpu(
        ctx: &GpuContext,
        keys: &[u32],
        bits: u32,
        capacity: u32,
    ) -> (Vec<u32>, Vec<u32>) {
        let device = &ctx.device;
        let values: Vec<u32> = (0..keys.len() as u32).collect();
        let init = |label, data: &[u32]| {
            let buf = kernel::storage(
                device,
                label,
                capacity as u64 * 4,
                wgpu::BufferUsages::empty(),
            );
            let data = &data[..data.len().min(capacity as usize)];
            ctx.queue.write_buffer(&buf, 0, bytemuck::cast_slice(data));
            buf
        };
        let k = init("keys", keys);
        let v = init("values", &values);
        let count = init("count", &[keys.len() as u32]);
        let sorter = RadixSort::new(device, capacity);
        let mut encoder = device.create_command_encoder(&Default::default());
        let at = {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            sorter.encode(device, &mut pass, &k, &v, &count, bits)
        };
        ctx.queue.submit([encoder.finish()]);
        let (kb, vb) = match at {
            SortedIn::Input => (&k, &v),
            SortedIn::Scratch => (sorter.scratch_keys(), sorter.scratch_values()),
        };
        let n = keys.len().min(capacity as usize);
        (
            readback::read_u32(ctx, kb, n).unwrap(),
            readback::read_u32(ctx, vb, n).unwrap(),
        )
    }

    /// The CPU twin: a stable sort by key of (key, original index).
    fn sort_on_cpu(keys: &[u32]) -> (Vec<u32>, Vec<u32>) {
        let mut pairs: Vec<(u32, u32)> = keys.iter().copied().zip(0..).collect();
        pairs.sort_by_key(|p| p.0);
        pairs.into_iter().unzip()
    }

    #[test]
    fn sort_matches_stable_cpu_sort_with_many_equal_keys() {
        let ctx = GpuContext::new().expect("a GPU adapter (lavapipe in CI)");
        let mut rng = fastrand::Rng::with_seed(7);
        // 11-bit keys (3 passes: result in scratch) with heavy duplication test stability.
        let keys: Vec<u32> = (0..70_001).map(|_| rng.u32(0..2000)).collect();
        let (gk, gv) = sort_on_gpu(&ctx, &keys, bits_for(1999), 80_000);
        let (ck, cv) = sort_on_cpu(&keys);
        assert_eq!(gk, ck);
        assert_eq!(gv, cv, "equal keys must keep their input order");
    }

    #[test]
    fn full_32_bit_keys_sort_like_the_cpu() {
        let ctx = GpuContext::new().expect("a GPU adapter (lavapipe in CI)");
        let mut rng = fastrand::Rng::with_seed(3);
        let mut keys: Vec<u32> = (0..5000).map(|_| rng.u32(..)).collect();
        keys.extend([u32::MAX, 0, u32::MAX, 1 << 31]);
        let (gk, gv) = sort_on_gpu(&ctx, &keys, 32, 5004);
        let (ck, cv) = sort_on_cpu(&keys);
        assert_eq!(gk, ck);
        assert_eq!(gv, cv);
    }

    #[test]
    fn count_above_capacity_is_clamped() {
        let ctx = GpuContext::new().expect("a GPU adapter (lavapipe in CI)");
        let keys: Vec<u32> = (0..3000u32).rev().collect();
        // Capacity 2048: only the first 2048 keys (3000-1 down to 952) are sorted.
        let (gk, _) = sort_on_gpu(&ctx, &keys[..], 12, 2048);
        let (ck, _) = sort_on_cpu(&keys[..2048]);
        assert_eq!(gk, ck);
    }
}
