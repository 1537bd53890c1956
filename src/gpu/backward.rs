//! Host side of the backward kernels: `shaders/rasterize_backward.wgsl` (per tile, pixel
//! gradients → per-Gaussian screen-space gradients) and `shaders/project_backward.wgsl` (per
//! Gaussian, screen-space → parameter gradients), and the buffers between them. They replay the
//! renderer's last forward (its projection, sorted intersections and per-pixel state).

use super::kernel::stage_source;
use super::kernel::{self, Bind};
use super::renderer::ForwardState;

const RASTERIZE_BACKWARD: &str = stage_source!("rasterize_backward.wgsl");
const PROJECT_BACKWARD: &str = stage_source!("project_backward.wgsl");

/// `add_grad` with the device's float atomics.
const ADD_FLOAT_ATOMIC: &str = "
@group(0) @binding(7) var<storage, read_write> screen_grads: array<atomic<f32>>;
fn add_grad(i: u32, v: f32) {
    if v != 0.0 {
        atomicAdd(&screen_grads[i], v);
    }
}
";

/// `add_grad` without float atomics: compare-and-swap on the bits until no other thread raced.
const ADD_COMPARE_SWAP: &str = "
@group(0) @binding(7) var<storage, read_write> screen_grads: array<atomic<u32>>;
fn add_grad(i: u32, v: f32) {
    if v == 0.0 {
        return;
    }
    var old = atomicLoad(&screen_grads[i]);
    loop {
        let swapped = atomicCompareExchangeWeak(&screen_grads[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if swapped.exchanged {
            break;
        }
        old = swapped.old_value;
    }
}
";

/// Screen-space gradient floats per Gaussian before its label channels (mean2d 2, conic 3,
/// colour 3, opacity, depth).
pub const SCREEN_FLOATS: usize = 10;
/// Floats per Gaussian in the parameter gradient buffer: mean 3, log-scale 3, rotation 4, raw
/// opacity, the densification statistic, the radius' bits, 3 unused.
pub const PARAM_FLOATS: usize = 16;
/// Floats per pixel of the uploaded pixel gradients before the label channels (r, g, b, alpha,
/// depth).
pub const PIXEL_FLOATS: usize = 5;

/// The backward's own buffers, sized by the model capacity, image and label count.
pub(super) struct BackwardBuffers {
    pub(super) gaussian_capacity: usize,
    pub(super) pixels: usize,
    pub(super) label_channels: usize,
    pub(super) sh_floats: usize,
    pub(super) v_pixels: wgpu::Buffer,
    pub(super) screen_grads: wgpu::Buffer,
    pub(super) param_grads: wgpu::Buffer,
    pub(super) v_sh: wgpu::Buffer,
    pub(super) v_raw_labels: wgpu::Buffer,
}

impl BackwardBuffers {
    pub(super) fn new(
        device: &wgpu::Device,
        gaussian_capacity: usize,
        pixels: usize,
        label_channels: usize,
        sh_floats: usize,
    ) -> BackwardBuffers {
        let none = wgpu::BufferUsages::empty();
        let n = gaussian_capacity as u64;
        let l = label_channels as u64;
        BackwardBuffers {
            gaussian_capacity,
            pixels,
            label_channels,
            sh_floats,
            v_pixels: kernel::storage(
                device,
                "v_pixels",
                pixels as u64 * (PIXEL_FLOATS as u64 + l) * 4,
                none,
            ),
            screen_grads: kernel::storage(
                device,
                "screen_grads",
                n * (SCREEN_FLOATS as u64 + l) * 4,
                none,
            ),
            param_grads: kernel::storage(device, "param_grads", n * PARAM_FLOATS as u64 * 4, none),
            v_sh: kernel::storage(device, "v_sh", n * sh_floats as u64 * 4, none),
            v_raw_labels: kernel::storage(device, "v_raw_labels", n * l * 4, none),
        }
    }

    pub(super) fn fits(
        &self,
        gaussian_capacity: usize,
        pixels: usize,
        label_channels: usize,
        sh_floats: usize,
    ) -> bool {
        self.gaussian_capacity >= gaussian_capacity
            && self.pixels == pixels
            && self.label_channels == label_channels
            && self.sh_floats == sh_floats
    }
}

/// The two backward pipelines.
pub struct BackwardStage {
    rasterize: wgpu::ComputePipeline,
    project: wgpu::ComputePipeline,
    float_atomics: bool,
}

impl BackwardStage {
    /// `float_atomics`: accumulate with the device's float atomic add (it must have
    /// `SHADER_FLOAT32_ATOMIC`); otherwise with a compare-and-swap loop.
    pub fn new(device: &wgpu::Device, float_atomics: bool) -> BackwardStage {
        let add = if float_atomics {
            ADD_FLOAT_ATOMIC
        } else {
            ADD_COMPARE_SWAP
        };
        let source = format!("{RASTERIZE_BACKWARD}{add}");
        BackwardStage {
            rasterize: kernel::pipeline(
                device,
                "rasterize_backward",
                &source,
                "rasterize_backward",
            ),
            project: kernel::pipeline(
                device,
                "project_backward",
                PROJECT_BACKWARD,
                "project_backward",
            ),
            float_atomics,
        }
    }

    pub fn float_atomics(&self) -> bool {
        self.float_atomics
    }

    /// Records the rasterize backward (screen gradients zeroed first) into `encoder`.
    pub(super) fn encode_rasterize(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        forward: &ForwardState<'_>,
        buffers: &BackwardBuffers,
    ) {
        encoder.clear_buffer(&buffers.screen_grads, 0, None);
        let group = kernel::bind_group(
            device,
            &self.rasterize,
            &[
                (0, Bind::Buffer(forward.uniforms)),
                (1, Bind::Buffer(forward.ranges)),
                (2, Bind::Buffer(forward.isect_gids)),
                (3, Bind::Buffer(forward.projected)),
                (4, Bind::Buffer(forward.labels)),
                (5, Bind::Buffer(forward.out_state)),
                (6, Bind::Buffer(&buffers.v_pixels)),
                (7, Bind::Buffer(&buffers.screen_grads)),
            ],
        );
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("rasterize_backward"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.rasterize);
        pass.set_bind_group(0, &group, &[]);
        let [tx, ty] = forward.tile_bounds;
        if tx > 0 && ty > 0 {
            pass.dispatch_workgroups(tx, ty, 1);
        }
    }

    /// Records the projection backward into `encoder`.
    pub(super) fn encode_project(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        forward: &ForwardState<'_>,
        buffers: &BackwardBuffers,
    ) {
        let group = kernel::bind_group(
            device,
            &self.project,
            &[
                (0, Bind::Buffer(forward.uniforms)),
                (1, Bind::Buffer(forward.geometry)),
                (2, Bind::Buffer(forward.sh)),
                (3, Bind::Buffer(forward.projected)),
                (4, Bind::Buffer(forward.labels)),
                (5, Bind::Buffer(&buffers.screen_grads)),
                (6, Bind::Buffer(&buffers.param_grads)),
                (7, Bind::Buffer(&buffers.v_sh)),
                (8, Bind::Buffer(&buffers.v_raw_labels)),
            ],
        );
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("project_backward"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.project);
        pass.set_bind_group(0, &group, &[]);
        kernel::dispatch(&mut pass, forward.num_gaussians.div_ceil(kernel::WORKGROUP));
    }
}
