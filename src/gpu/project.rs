//! Host side of `shaders/project.wgsl` (stage 1: project + cull), and the two layouts every splat
//! stage shares with `shaders/common.wgsl`: the per-frame uniforms and the projected splat.

use super::kernel::{self, Bind, stage_source};
use super::render_settings::GpuRenderSettings;
use super::splat_buffers::SplatBuffers;
use crate::scene::Camera;
use bytemuck::{Pod, Zeroable};

const SHADER: &str = stage_source!("project.wgsl");

/// Tile edge in pixels (as the CPU reference).
pub const TILE_SIZE: u32 = 16;
/// Near plane: Gaussians whose camera-space depth is not above it are culled (gsplat's 0.01).
pub const NEAR_PLANE: f32 = 0.01;
/// Most label channels the kernels blend (a private array in the rasterizer).
pub const MAX_LABELS: usize = crate::splats::MAX_LABEL_CHANNELS;

/// Per-frame uniforms, byte for byte `Uniforms` in `shaders/common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct FrameUniforms {
    pub rot0: [f32; 4],
    pub rot1: [f32; 4],
    pub rot2: [f32; 4],
    pub trans: [f32; 4],
    pub cam_pos: [f32; 4],
    pub background: [f32; 4],
    pub focal: [f32; 2],
    pub principal: [f32; 2],
    pub img_size: [u32; 2],
    pub tile_bounds: [u32; 2],
    pub num_gaussians: u32,
    pub sh_degree: u32,
    pub sh_coeffs: u32,
    pub label_channels: u32,
    pub near: f32,
    pub log_scales_at: u32,
    pub rotations_at: u32,
    pub opacities_at: u32,
    pub isect_capacity: u32,
    pub alpha_max: f32,
    /// Backward only: 1 when colour gradients flow through the SH view direction to the means.
    pub sh_direction_grad: u32,
    pub pad: u32,
}

/// Tiles across and down for an image size.
pub fn tile_bounds(width: u32, height: u32) -> [u32; 2] {
    [width.div_ceil(TILE_SIZE), height.div_ceil(TILE_SIZE)]
}

impl FrameUniforms {
    /// Uniforms for `camera` over the splats in `buffers` (the active SH degree is clamped to
    /// the stored one).
    pub fn new(
        camera: &Camera,
        settings: &GpuRenderSettings,
        buffers: &SplatBuffers,
        isect_capacity: u32,
    ) -> FrameUniforms {
        let r = camera.rotation_matrix();
        // glam matrices are column-major: row i is (col0[i], col1[i], col2[i]).
        let row = |i: usize| [r.x_axis[i], r.y_axis[i], r.z_axis[i], 0.0];
        let k = &camera.intrinsics;
        let layout = buffers.layout();
        FrameUniforms {
            rot0: row(0),
            rot1: row(1),
            rot2: row(2),
            trans: camera.translation.extend(0.0).to_array(),
            cam_pos: camera.position().extend(0.0).to_array(),
            background: settings.background.extend(1.0).to_array(),
            focal: [k.fx, k.fy],
            principal: [k.cx, k.cy],
            img_size: [k.width, k.height],
            tile_bounds: tile_bounds(k.width, k.height),
            num_gaussians: buffers.len() as u32,
            sh_degree: settings.sh_degree.min(buffers.sh_degree()),
            sh_coeffs: crate::splats::model::sh_coeffs_for_degree(buffers.sh_degree()) as u32,
            label_channels: buffers.label_channels() as u32,
            near: NEAR_PLANE,
            log_scales_at: layout.log_scales_at,
            rotations_at: layout.rotations_at,
            opacities_at: layout.opacities_at,
            isect_capacity,
            alpha_max: settings.alpha_max,
            sh_direction_grad: settings.sh_direction_grad as u32,
            pad: 0,
        }
    }
}

/// One projected Gaussian, byte for byte `ProjectedSplat` in `shaders/common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ProjectedSplat {
    pub xy: [f32; 2],
    pub depth: f32,
    pub opacity: f32,
    /// Inverse 2D covariance (a, b, c).
    pub conic: [f32; 3],
    /// 0 when culled.
    pub radius: u32,
    pub color: [f32; 3],
    pub tiles: u32,
    pub rect_x: u32,
    pub rect_y: u32,
    pub pad: [u32; 2],
}

/// Bytes per projected splat on the GPU.
pub const PROJECTED_BYTES: u64 = std::mem::size_of::<ProjectedSplat>() as u64;

/// The projection stage's outputs, per Gaussian in input order.
pub struct ProjectOutputs<'a> {
    pub projected: &'a wgpu::Buffer,
    pub depth_keys: &'a wgpu::Buffer,
    pub depth_gids: &'a wgpu::Buffer,
    pub labels: &'a wgpu::Buffer,
}

pub struct ProjectStage {
    pipeline: wgpu::ComputePipeline,
}

impl ProjectStage {
    pub fn new(device: &wgpu::Device) -> ProjectStage {
        ProjectStage {
            pipeline: kernel::pipeline(device, "project", SHADER, "project"),
        }
    }

    pub fn encode(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu::ComputePass<'_>,
        uniforms: &wgpu::Buffer,
        splats: &SplatBuffers,
        out: &ProjectOutputs<'_>,
    ) {
        let group = kernel::bind_group(
            device,
            &self.pipeline,
            &[
                (0, Bind::Buffer(uniforms)),
                (1, Bind::Buffer(splats.geometry())),
                (2, Bind::Buffer(splats.sh())),
                (3, Bind::Buffer(splats.raw_labels())),
                (4, Bind::Buffer(out.projected)),
                (5, Bind::Buffer(out.depth_keys)),
                (6, Bind::Buffer(out.depth_gids)),
                (7, Bind::Buffer(out.labels)),
            ],
        );
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        kernel::dispatch(pass, (splats.len() as u32).div_ceil(kernel::WORKGROUP));
    }
}
