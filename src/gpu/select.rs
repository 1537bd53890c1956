//! Selection on the GPU (`shaders/select.wgsl`): which Gaussians a screen shape (rectangle,
//! polygon, brush) or a volume (sphere, box) takes, straight through or front-most, with the
//! rules of the CPU's `splats::selection::hits` and `damage::pick::front_hits`. One thread per
//! Gaussian and a bit per Gaussian read back, so a 1M-Gaussian selection costs one small
//! dispatch (plus, front-most, one forward render at the camera). The model is uploaded once per
//! `model_key`; the state bits every call.

use bytemuck::{Pod, Zeroable};
use glam::Vec2;

use super::kernel::{self, Bind};
use super::{GpuContext, GpuError, GpuRenderSettings, GpuRenderer, readback};
use crate::scene::Camera;
use crate::splats::Splats;
use crate::splats::model::state::{DELETED, HIDDEN};
use crate::splats::selection::Shape;

const SHADER: &str = include_str!("../../shaders/select.wgsl");

/// Byte for byte `SelectUniforms` in `shaders/select.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct SelectUniforms {
    rot0: [f32; 4],
    rot1: [f32; 4],
    rot2: [f32; 4],
    trans: [f32; 4],
    a: [f32; 4],
    b: [f32; 4],
    focal: [f32; 2],
    principal: [f32; 2],
    img_size: [u32; 2],
    num_gaussians: u32,
    kind: u32,
    points: u32,
    front_most: u32,
    radius: f32,
    log_scales_at: u32,
}

/// The selection pass with its own renderer (the drawn model and, front-most, its depth).
pub struct GpuSelector {
    renderer: GpuRenderer,
    pipeline: wgpu::ComputePipeline,
    model_key: Option<u64>,
}

impl GpuSelector {
    pub fn new(ctx: &GpuContext) -> Result<GpuSelector, GpuError> {
        Ok(GpuSelector {
            renderer: GpuRenderer::new(ctx)?,
            pipeline: kernel::pipeline(&ctx.device, "select", SHADER, "select_hits"),
            model_key: None,
        })
    }

    /// Per Gaussian of `splats`: inside `shape` seen from `camera`, and when `front_most` is
    /// given (the render settings of the surface test) not behind the surface drawn there.
    /// `model_key` must change whenever the positions, scales, opacities or hidden/deleted bits
    /// change (the drawn model is uploaded again then).
    pub fn hits(
        &mut self,
        splats: &Splats,
        model_key: u64,
        camera: &Camera,
        shape: &Shape,
        front_most: Option<&GpuRenderSettings>,
    ) -> Result<Vec<bool>, GpuError> {
        let n = splats.len();
        if n == 0 {
            return Ok(Vec::new());
        }
        if self.model_key != Some(model_key) || self.renderer.splat_buffers().len() != n {
            // Hidden and deleted Gaussians neither draw nor occlude (as `damage::pick`).
            let mut drawn = splats.clone();
            for (opacity, &bits) in drawn.raw_opacities.iter_mut().zip(&splats.meta.state) {
                if bits & (HIDDEN | DELETED) != 0 {
                    *opacity = -30.0;
                }
            }
            self.renderer.upload(&drawn)?;
            self.model_key = Some(model_key);
        }
        let front = front_most.is_some() && shape.screen_bounds().is_some();
        if let Some(settings) = front_most.filter(|_| front) {
            self.renderer.render_blocking(camera, settings)?;
        }
        let ctx = self.renderer.context().clone();
        let device = &ctx.device;
        let (kind, a, b, radius, points): (u32, [f32; 4], [f32; 4], f32, &[Vec2]) = match shape {
            Shape::Rect { a, b } => (0, [a.x, a.y, 0.0, 0.0], [b.x, b.y, 0.0, 0.0], 0.0, &[]),
            Shape::Polygon(points) => (1, [0.0; 4], [0.0; 4], 0.0, points),
            Shape::Brush { centres, radius } => (2, [0.0; 4], [0.0; 4], *radius, centres),
            Shape::Sphere { centre, radius } => {
                (3, centre.extend(0.0).to_array(), [0.0; 4], *radius, &[])
            }
            Shape::Box { a, b } => (
                4,
                a.extend(0.0).to_array(),
                b.extend(0.0).to_array(),
                0.0,
                &[],
            ),
        };
        let r = camera.rotation_matrix();
        let row = |i: usize| [r.x_axis[i], r.y_axis[i], r.z_axis[i], 0.0];
        let k = camera.intrinsics;
        let uniforms = SelectUniforms {
            rot0: row(0),
            rot1: row(1),
            rot2: row(2),
            trans: camera.translation.extend(0.0).to_array(),
            a,
            b,
            focal: [k.fx, k.fy],
            principal: [k.cx, k.cy],
            img_size: [k.width, k.height],
            num_gaussians: n as u32,
            kind,
            points: points.len() as u32,
            front_most: front as u32,
            radius,
            log_scales_at: self.renderer.splat_buffers().layout().log_scales_at,
        };
        let uniform_buffer = kernel::uniform::<SelectUniforms>(device, "select uniforms");
        ctx.queue
            .write_buffer(&uniform_buffer, 0, bytemuck::bytes_of(&uniforms));
        let none = wgpu::BufferUsages::empty();
        let state: Vec<u32> = splats.meta.state.iter().map(|&s| u32::from(s)).collect();
        let state_buffer = kernel::storage(device, "select state", n as u64 * 4, none);
        ctx.queue
            .write_buffer(&state_buffer, 0, bytemuck::cast_slice(&state));
        let flat: Vec<f32> = points.iter().flat_map(|p| [p.x, p.y]).collect();
        let points_buffer = kernel::storage(device, "select points", flat.len() as u64 * 4, none);
        if !flat.is_empty() {
            ctx.queue
                .write_buffer(&points_buffer, 0, bytemuck::cast_slice(&flat));
        }
        let words = n.div_ceil(32);
        let hits_buffer = kernel::storage(device, "select hits", words as u64 * 4, none);
        // Straight through, nothing reads the frame; a one-pixel stand-in keeps the layout.
        let spare = kernel::storage(device, "select no frame", 16, none);
        let frame = self.renderer.forward_state().filter(|_| front);
        let (color, depth) = match &frame {
            Some(f) => (f.out_color, f.out_depth),
            None => (&spare, &spare),
        };
        let group = kernel::bind_group(
            device,
            &self.pipeline,
            &[
                (0, Bind::Buffer(&uniform_buffer)),
                (1, Bind::Buffer(self.renderer.splat_buffers().geometry())),
                (2, Bind::Buffer(&state_buffer)),
                (3, Bind::Buffer(&points_buffer)),
                (4, Bind::Buffer(color)),
                (5, Bind::Buffer(depth)),
                (6, Bind::Buffer(&hits_buffer)),
            ],
        );
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("select"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &group, &[]);
            kernel::dispatch(&mut pass, (n as u32).div_ceil(kernel::WORKGROUP));
        }
        ctx.queue.submit([encoder.finish()]);
        let bits = readback::read_u32(&ctx, &hits_buffer, words)?;
        Ok((0..n).map(|g| bits[g / 32] >> (g % 32) & 1 == 1).collect())
    }
}
