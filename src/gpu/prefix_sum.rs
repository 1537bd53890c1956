//! Host side of `shaders/prefix_sum.wgsl`: an in-place exclusive scan of `u32` over a buffer,
//! multi-level (512 elements per block per level). The length is either known on the host
//! ([`ScanLen::Host`]) or written on the GPU into [`PrefixSum::len_buffer`] by an earlier kernel.

use super::kernel::{self, Bind};

/// Elements per block (256 threads × 2), as in the shader.
pub const BLOCK: u32 = 512;
/// Words between two levels' lengths in the length buffer (256 bytes: any storage offset alignment).
pub const LEN_STRIDE_WORDS: u32 = 64;

const SHADER: &str = include_str!("../../shaders/prefix_sum.wgsl");

/// Where the element count comes from.
#[derive(Clone, Copy, Debug)]
pub enum ScanLen {
    /// Known on the host; dispatch sizes are exact.
    Host(u32),
    /// Already written on the GPU into `len_buffer` for every level (word `level * 64`);
    /// dispatches cover the capacity and idle workgroups do nothing.
    Device,
}

/// A scan plan for up to `capacity` elements: pipelines plus the per-level block-total buffers.
pub struct PrefixSum {
    scan_blocks: wgpu::ComputePipeline,
    add_offsets: wgpu::ComputePipeline,
    capacity: u32,
    /// Capacity of each level: level 0 is the data, level l+1 the block totals of level l.
    level_caps: Vec<u32>,
    /// `sums[l]` holds the block totals of level l (the data of level l+1); the last one has
    /// a single element: the grand total.
    sums: Vec<wgpu::Buffer>,
    len: wgpu::Buffer,
}

/// Capacities of the levels of a scan over `capacity` elements (the last has at most one block).
pub fn level_capacities(capacity: u32) -> Vec<u32> {
    let mut caps = vec![capacity.max(1)];
    while *caps.last().unwrap_or(&1) > BLOCK {
        let next = caps[caps.len() - 1].div_ceil(BLOCK);
        caps.push(next);
    }
    caps
}

impl PrefixSum {
    pub fn new(device: &wgpu::Device, capacity: u32) -> PrefixSum {
        let pipelines =
            kernel::pipelines(device, "prefix_sum", SHADER, ["scan_blocks", "add_offsets"]);
        Self::with_pipelines(device, pipelines, capacity)
    }

    /// The same scan for another capacity: new buffers, the same compiled pipelines.
    pub fn resized(&self, device: &wgpu::Device, capacity: u32) -> PrefixSum {
        Self::with_pipelines(
            device,
            [self.scan_blocks.clone(), self.add_offsets.clone()],
            capacity,
        )
    }

    fn with_pipelines(
        device: &wgpu::Device,
        [scan_blocks, add_offsets]: [wgpu::ComputePipeline; 2],
        capacity: u32,
    ) -> PrefixSum {
        let level_caps = level_capacities(capacity);
        let sums = level_caps
            .iter()
            .map(|&c| {
                kernel::storage(
                    device,
                    "prefix_sum.block_sums",
                    c.div_ceil(BLOCK) as u64 * 4,
                    wgpu::BufferUsages::empty(),
                )
            })
            .collect();
        let len = kernel::storage(
            device,
            "prefix_sum.len",
            level_caps.len() as u64 * LEN_STRIDE_WORDS as u64 * 4,
            wgpu::BufferUsages::empty(),
        );
        PrefixSum {
            scan_blocks,
            add_offsets,
            capacity,
            level_caps,
            sums,
            len,
        }
    }

    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Number of levels (what a GPU-side writer of the lengths must fill).
    pub fn levels(&self) -> u32 {
        self.level_caps.len() as u32
    }

    /// The per-level lengths, word `level * LEN_STRIDE_WORDS`, for [`ScanLen::Device`].
    pub fn len_buffer(&self) -> &wgpu::Buffer {
        &self.len
    }

    /// The grand total of the last scan (one `u32`), valid after the scan has run.
    pub fn total_buffer(&self) -> &wgpu::Buffer {
        &self.sums[self.sums.len() - 1]
    }

    /// Writes host-known per-level lengths (must happen before the submit that scans).
    pub fn write_len(&self, queue: &wgpu::Queue, n: u32) {
        let mut words = vec![0u32; self.level_caps.len() * LEN_STRIDE_WORDS as usize];
        let mut level_n = n;
        for l in 0..self.level_caps.len() {
            words[l * LEN_STRIDE_WORDS as usize] = level_n;
            level_n = level_n.div_ceil(BLOCK);
        }
        queue.write_buffer(&self.len, 0, bytemuck::cast_slice(&words));
    }

    /// Encodes the in-place exclusive scan of `data` (at least `len` u32s). For
    /// [`ScanLen::Host`], call [`PrefixSum::write_len`] with the same `n` before submitting.
    pub fn encode(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu::ComputePass<'_>,
        data: &wgpu::Buffer,
        len: ScanLen,
    ) {
        let levels = self.level_caps.len();
        let mut groups = Vec::with_capacity(levels);
        let mut scan_groups = Vec::with_capacity(levels);
        let mut add_groups = Vec::with_capacity(levels);
        let mut host_n = match len {
            ScanLen::Host(n) => Some(n.min(self.capacity)),
            ScanLen::Device => None,
        };
        for l in 0..levels {
            let level_data = if l == 0 { data } else { &self.sums[l - 1] };
            // Auto layouts are per pipeline, so each kernel gets its own bind group.
            for (pipeline, out) in [
                (&self.scan_blocks, &mut scan_groups),
                (&self.add_offsets, &mut add_groups),
            ] {
                out.push(kernel::bind_group(
                    device,
                    pipeline,
                    &[
                        (
                            0,
                            Bind::Range(&self.len, (l as u32 * LEN_STRIDE_WORDS * 4) as u64, 4),
                        ),
                        (1, Bind::Buffer(level_data)),
                        (2, Bind::Buffer(&self.sums[l])),
                    ],
                ));
            }
            let cap = self.level_caps[l];
            groups.push(match host_n {
                Some(n) => n.div_ceil(BLOCK),
                None => cap.div_ceil(BLOCK),
            });
            host_n = host_n.map(|n| n.div_ceil(BLOCK));
        }
        pass.set_pipeline(&self.scan_blocks);
        for l in 0..levels {
            pass.set_bind_group(0, &scan_groups[l], &[]);
            kernel::dispatch(pass, groups[l]);
        }
        // Level l's blocks receive the scanned totals of level l+1, top level first.
        pass.set_pipeline(&self.add_offsets);
        for l in (0..levels.saturating_sub(1)).rev() {
            pass.set_bind_group(0, &add_groups[l], &[]);
            kernel::dispatch(pass, groups[l]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::{GpuContext, readback};

    fn cpu_exclusive_scan(values: &[u32]) -> Vec<u32> {
        let mut acc = 0u32;
        values
            .iter()
            .map(|&v| {
                let out = acc;
                acc = acc.wrapping_add(v);
                out
            })
            .collect()
    }

    fn gpu_scan(ctx: &GpuContext, values: &[u32], capacity: u32) -> (Vec<u32>, u32) {
        let data = kernel::storage(
            &ctx.device,
            "data",
            capacity as u64 * 4,
            wgpu::BufferUsages::empty(),
        );
        ctx.queue
            .write_buffer(&data, 0, bytemuck::cast_slice(values));
        let scan = PrefixSum::new(&ctx.device, capacity);
        scan.write_len(&ctx.queue, values.len() as u32);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            scan.encode(
                &ctx.device,
                &mut pass,
                &data,
                ScanLen::Host(values.len() as u32),
            );
        }
        ctx.queue.submit([encoder.finish()]);
        let out = readback::read_u32(ctx, &data, values.len()).unwrap();
        let total = readback::read_u32(ctx, scan.total_buffer(), 1).unwrap()[0];
        (out, total)
    }

    #[test]
    fn exclusive_scan_matches_cpu_across_three_levels() {
        let ctx = GpuContext::new().expect("a GPU adapter (lavapipe in CI)");
        let mut rng = fastrand::Rng::with_seed(11);
        // 300k elements: 586 blocks at level 0, 2 at level 1, 1 at level 2.
        for n in [1usize, 511, 512, 513, 300_001] {
            let values: Vec<u32> = (0..n).map(|_| rng.u32(0..50)).collect();
            let (got, total) = gpu_scan(&ctx, &values, n as u32 + 17);
            assert_eq!(got, cpu_exclusive_scan(&values), "n = {n}");
            assert_eq!(total, values.iter().sum::<u32>(), "n = {n}");
        }
    }

    #[test]
    fn level_capacities_end_in_one_block() {
        assert_eq!(level_capacities(512), vec![512]);
        assert_eq!(level_capacities(513), vec![513, 2]);
        assert_eq!(level_capacities(512 * 512 + 1), vec![262_145, 513, 2]);
    }
}
