//! Host side of `shaders/tile_ranges.wgsl` (stage 5): per tile, the [start, end) run of its
//! intersections in the tile-sorted list. Dispatched indirectly from the tile sort's GPU-side
//! sizes (same 1024 elements per workgroup), so the count is never read back.

use super::kernel::stage_source;
use super::kernel::{self, Bind};

const SHADER: &str = stage_source!("tile_ranges.wgsl");

pub struct TileRangesStage {
    clear: wgpu::ComputePipeline,
    ranges: wgpu::ComputePipeline,
}

impl TileRangesStage {
    pub fn new(device: &wgpu::Device) -> TileRangesStage {
        let [clear, ranges] = kernel::pipelines(
            device,
            "tile_ranges",
            SHADER,
            ["clear_ranges", "tile_ranges"],
        );
        TileRangesStage { clear, ranges }
    }

    /// `sizes`/`dispatch_args` are the tile sort's ([`super::radix_sort::RadixSort::sizes`]).
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu::ComputePass<'_>,
        uniforms: &wgpu::Buffer,
        sizes: &wgpu::Buffer,
        dispatch_args: &wgpu::Buffer,
        sorted_tile_keys: &wgpu::Buffer,
        ranges: &wgpu::Buffer,
        num_tiles: u32,
    ) {
        let clear = kernel::bind_group(
            device,
            &self.clear,
            &[(0, Bind::Buffer(uniforms)), (3, Bind::Buffer(ranges))],
        );
        pass.set_pipeline(&self.clear);
        pass.set_bind_group(0, &clear, &[]);
        kernel::dispatch(pass, num_tiles.div_ceil(kernel::WORKGROUP));
        let group = kernel::bind_group(
            device,
            &self.ranges,
            &[
                (1, Bind::Buffer(sizes)),
                (2, Bind::Buffer(sorted_tile_keys)),
                (3, Bind::Buffer(ranges)),
            ],
        );
        pass.set_pipeline(&self.ranges);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups_indirect(dispatch_args, 0);
    }
}
