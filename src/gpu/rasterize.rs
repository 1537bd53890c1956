//! Host side of `shaders/rasterize.wgsl` (stage 6): one 16×16 workgroup per tile blending its
//! depth-ordered Gaussians into colour, alpha, depth, label channels and a display texture.

use super::kernel::stage_source;
use super::kernel::{self, Bind};

const SHADER: &str = stage_source!("rasterize.wgsl");

/// What the rasterizer reads and writes.
pub struct RasterBuffers<'a> {
    pub uniforms: &'a wgpu::Buffer,
    pub ranges: &'a wgpu::Buffer,
    pub isect_gids: &'a wgpu::Buffer,
    pub projected: &'a wgpu::Buffer,
    pub labels: &'a wgpu::Buffer,
    /// vec4 per pixel: RGB composited on the background, alpha.
    pub out_color: &'a wgpu::Buffer,
    pub out_depth: &'a wgpu::Buffer,
    pub out_labels: &'a wgpu::Buffer,
    pub out_texture: &'a wgpu::TextureView,
    /// Per pixel the final transmittance's bits and its blended count (the backward's start).
    pub out_state: &'a wgpu::Buffer,
}

pub struct RasterizeStage {
    pipeline: wgpu::ComputePipeline,
}

impl RasterizeStage {
    pub fn new(device: &wgpu::Device) -> RasterizeStage {
        RasterizeStage {
            pipeline: kernel::pipeline(device, "rasterize", SHADER, "rasterize"),
        }
    }

    pub fn encode(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu::ComputePass<'_>,
        b: &RasterBuffers<'_>,
        tile_bounds: [u32; 2],
    ) {
        let group = kernel::bind_group(
            device,
            &self.pipeline,
            &[
                (0, Bind::Buffer(b.uniforms)),
                (1, Bind::Buffer(b.ranges)),
                (2, Bind::Buffer(b.isect_gids)),
                (3, Bind::Buffer(b.projected)),
                (4, Bind::Buffer(b.labels)),
                (5, Bind::Buffer(b.out_color)),
                (6, Bind::Buffer(b.out_depth)),
                (7, Bind::Buffer(b.out_labels)),
                (8, Bind::Texture(b.out_texture)),
                (9, Bind::Buffer(b.out_state)),
            ],
        );
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        if tile_bounds[0] > 0 && tile_bounds[1] > 0 {
            pass.dispatch_workgroups(tile_bounds[0], tile_bounds[1], 1);
        }
    }
}
