//! Host side of `shaders/emit_intersections.wgsl` (stage 3): per-Gaussian tile counts laid out
//! in depth order, scanned into write offsets, then one (tile, gaussian) pair per intersection.
//! The total stays on the GPU (`isect_count`); nothing here reads it back.

use super::kernel::stage_source;
use super::kernel::{self, Bind};
use super::prefix_sum::{PrefixSum, ScanLen};

const SHADER: &str = stage_source!("emit_intersections.wgsl");

/// Buffers the emission reads and writes.
pub struct EmitBuffers<'a> {
    pub uniforms: &'a wgpu::Buffer,
    pub projected: &'a wgpu::Buffer,
    /// Gaussian ids in depth order (the depth sort's values).
    pub sorted_gids: &'a wgpu::Buffer,
    /// Scratch, one u32 per Gaussian: counts, then exclusive offsets.
    pub offsets: &'a wgpu::Buffer,
    pub tile_keys: &'a wgpu::Buffer,
    pub isect_gids: &'a wgpu::Buffer,
    /// One u32: the unclamped number of intersections (cleared by the caller each frame).
    pub isect_count: &'a wgpu::Buffer,
}

pub struct EmitStage {
    gather_counts: wgpu::ComputePipeline,
    emit: wgpu::ComputePipeline,
}

impl EmitStage {
    pub fn new(device: &wgpu::Device) -> EmitStage {
        let [gather_counts, emit] =
            kernel::pipelines(device, "emit", SHADER, ["gather_counts", "emit"]);
        EmitStage {
            gather_counts,
            emit,
        }
    }

    /// The counts and offsets part: gather in depth order, then scan (the scan's length must
    /// have been written with `scan.write_len(queue, num_gaussians)`).
    pub fn encode_offsets(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu::ComputePass<'_>,
        scan: &PrefixSum,
        b: &EmitBuffers<'_>,
        num_gaussians: u32,
    ) {
        let group = kernel::bind_group(
            device,
            &self.gather_counts,
            &[
                (0, Bind::Buffer(b.uniforms)),
                (1, Bind::Buffer(b.projected)),
                (2, Bind::Buffer(b.sorted_gids)),
                (3, Bind::Buffer(b.offsets)),
            ],
        );
        pass.set_pipeline(&self.gather_counts);
        pass.set_bind_group(0, &group, &[]);
        kernel::dispatch(pass, num_gaussians.div_ceil(kernel::WORKGROUP));
        scan.encode(device, pass, b.offsets, ScanLen::Host(num_gaussians));
    }

    /// Writes the intersection pairs and the total.
    pub fn encode_emit(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu::ComputePass<'_>,
        b: &EmitBuffers<'_>,
        num_gaussians: u32,
    ) {
        let group = kernel::bind_group(
            device,
            &self.emit,
            &[
                (0, Bind::Buffer(b.uniforms)),
                (1, Bind::Buffer(b.projected)),
                (2, Bind::Buffer(b.sorted_gids)),
                (3, Bind::Buffer(b.offsets)),
                (4, Bind::Buffer(b.tile_keys)),
                (5, Bind::Buffer(b.isect_gids)),
                (6, Bind::Buffer(b.isect_count)),
            ],
        );
        pass.set_pipeline(&self.emit);
        pass.set_bind_group(0, &group, &[]);
        kernel::dispatch(pass, num_gaussians.div_ceil(kernel::WORKGROUP));
    }
}
