//! Host side of `shaders/loss.wgsl`: the training loss (L1 + D-SSIM, label cross-entropy, loss
//! regions) and its gradient computed on the GPU from the renderer's frame, written straight into
//! the backward's pixel gradients, so a resident step reads back neither the frame nor the
//! gradients: only per-workgroup partial sums of the loss.

use bytemuck::{Pod, Zeroable};

use super::kernel::{self, Bind};
use super::{GpuContext, GpuError, readback};

const SHADER: &str = include_str!("../../shaders/loss.wgsl");
/// Floats per workgroup in `partials`: SSIM, L1 and label loss sums.
const PARTIALS: usize = 3;
/// SSIM statistics planes (x, y, x², y², xy per channel) and backward planes.
const FORWARD_PLANES: u32 = 15;
const BACKWARD_PLANES: u32 = 9;

/// The loss's weights (the trainer's `Targets` and `LabelLossParams`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossWeights {
    pub ssim_lambda: f32,
    pub rgb_weight: f32,
    pub label_weight: f32,
    pub pos_weight: f32,
    pub eps: f32,
    /// SSIM's normalised 1D Gaussian window (`train::ssim::gaussian_window`).
    pub window: [f32; 11],
}

/// One view's targets: the photo (RGB interleaved), the loss region's per-pixel weights, and per
/// label channel its mask (None: unsupervised).
pub struct LossTarget<'a> {
    pub photo: &'a [f32],
    pub region: Option<&'a [f32]>,
    pub labels: &'a [Option<&'a [u8]>],
}

/// Byte for byte `LossUniforms` in `shaders/loss.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct LossUniforms {
    width: u32,
    height: u32,
    label_channels: u32,
    supervised: u32,
    planes: u32,
    ssim_lambda: f32,
    rgb_weight: f32,
    label_weight: f32,
    pos_weight: f32,
    eps: f32,
    pixel_scale: f32,
    label_scale: f32,
    kernel: [[f32; 4]; 3],
}

struct LossBuffers {
    width: u32,
    height: u32,
    label_channels: usize,
    targets: wgpu::Buffer,
    label_targets: wgpu::Buffer,
    planes: wgpu::Buffer,
    tmp: wgpu::Buffer,
    back: wgpu::Buffer,
    partials: wgpu::Buffer,
    /// Uniforms with `planes` = 0, 15 and 9.
    uniforms: [wgpu::Buffer; 3],
}

/// The loss stage: five kernels and their buffers, sized by the image and label count.
pub struct GpuLoss {
    prepare: wgpu::ComputePipeline,
    blur_h: wgpu::ComputePipeline,
    blur_v: wgpu::ComputePipeline,
    ssim_maps: wgpu::ComputePipeline,
    combine: wgpu::ComputePipeline,
    buffers: Option<LossBuffers>,
    weights: Option<LossWeights>,
    /// The view's region has no pixel: the photometric loss is zero (as on the CPU).
    empty_region: bool,
}

impl GpuLoss {
    pub fn new(device: &wgpu::Device) -> GpuLoss {
        let [prepare, blur_h, blur_v, ssim_maps, combine] = kernel::pipelines(
            device,
            "loss",
            SHADER,
            ["ssim_prepare", "blur_h", "blur_v", "ssim_maps", "combine"],
        );
        GpuLoss {
            prepare,
            blur_h,
            blur_v,
            ssim_maps,
            combine,
            buffers: None,
            weights: None,
            empty_region: false,
        }
    }

    /// Uploads one view's targets for a `width × height` render with `label_channels` channels.
    pub fn set_target(
        &mut self,
        ctx: &GpuContext,
        width: u32,
        height: u32,
        label_channels: usize,
        target: &LossTarget,
        weights: &LossWeights,
    ) -> Result<(), GpuError> {
        let n = width as usize * height as usize;
        let bad = |what: &str| GpuError::InvalidSplats(format!("loss target: {what}"));
        if target.photo.len() != n * 3 {
            return Err(bad("photo size"));
        }
        if target.region.is_some_and(|r| r.len() != n) {
            return Err(bad("region size"));
        }
        if target.labels.len() != label_channels || label_channels > 32 {
            return Err(bad("one label mask per channel"));
        }
        if target.labels.iter().flatten().any(|m| m.len() != n) {
            return Err(bad("label mask size"));
        }
        let device = &ctx.device;
        let fits = self.buffers.as_ref().is_some_and(|b| {
            b.width == width && b.height == height && b.label_channels == label_channels
        });
        if !fits {
            let none = wgpu::BufferUsages::empty();
            let groups = n.div_ceil(kernel::WORKGROUP as usize);
            let uniform = || kernel::uniform::<LossUniforms>(device, "loss uniforms");
            let planes = |count: u32| (n * count as usize * 4) as u64;
            self.buffers = Some(LossBuffers {
                width,
                height,
                label_channels,
                targets: kernel::storage(device, "loss targets", (n * 16) as u64, none),
                label_targets: kernel::storage(device, "loss label targets", (n * 4) as u64, none),
                planes: kernel::storage(device, "ssim planes", planes(FORWARD_PLANES), none),
                tmp: kernel::storage(device, "ssim blur", planes(FORWARD_PLANES), none),
                back: kernel::storage(device, "ssim partials", planes(BACKWARD_PLANES), none),
                partials: kernel::storage(
                    device,
                    "loss partial sums",
                    (groups * PARTIALS * 4) as u64,
                    none,
                ),
                uniforms: [uniform(), uniform(), uniform()],
            });
        }
        let buffers = self
            .buffers
            .as_ref()
            .ok_or(GpuError::Device("loss buffers missing".into()))?;
        let mut packed = Vec::with_capacity(n * 4);
        for p in 0..n {
            packed.extend_from_slice(&target.photo[p * 3..p * 3 + 3]);
            packed.push(target.region.map_or(1.0, |r| r[p]));
        }
        let mut bits = vec![0u32; n];
        let mut supervised = 0u32;
        for (k, mask) in target.labels.iter().enumerate() {
            let Some(mask) = mask else { continue };
            supervised |= 1 << k;
            for (b, &v) in bits.iter_mut().zip(mask.iter()) {
                if v != 0 {
                    *b |= 1 << k;
                }
            }
        }
        let mass: f64 = target
            .region
            .map_or(n as f64, |r| r.iter().map(|&v| v as f64).sum());
        self.empty_region = !(mass > 0.0);
        let supervised_count = supervised.count_ones() as f64;
        let label_total = mass * supervised_count;
        let mut kernel_rows = [[0.0f32; 4]; 3];
        for (i, w) in weights.window.iter().enumerate() {
            kernel_rows[i / 4][i % 4] = *w;
        }
        let base = LossUniforms {
            width,
            height,
            label_channels: label_channels as u32,
            supervised,
            planes: 0,
            ssim_lambda: weights.ssim_lambda,
            rgb_weight: weights.rgb_weight,
            label_weight: weights.label_weight,
            pos_weight: weights.pos_weight,
            eps: weights.eps,
            pixel_scale: if self.empty_region {
                0.0
            } else {
                (1.0 / (3.0 * mass)) as f32
            },
            label_scale: if label_total > 0.0 {
                (1.0 / label_total) as f32
            } else {
                0.0
            },
            kernel: kernel_rows,
        };
        let q = &ctx.queue;
        for (buffer, planes) in buffers
            .uniforms
            .iter()
            .zip([0, FORWARD_PLANES, BACKWARD_PLANES])
        {
            q.write_buffer(
                buffer,
                0,
                bytemuck::bytes_of(&LossUniforms { planes, ..base }),
            );
        }
        q.write_buffer(&buffers.targets, 0, bytemuck::cast_slice(&packed));
        q.write_buffer(&buffers.label_targets, 0, bytemuck::cast_slice(&bits));
        self.weights = Some(*weights);
        Ok(())
    }

    /// Records the loss and its gradient of the frame in `out_color` / `out_labels` into
    /// `v_pixels` (stride 5 + label channels).
    pub(super) fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        out_color: &wgpu::Buffer,
        out_labels: &wgpu::Buffer,
        v_pixels: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        let b = self
            .buffers
            .as_ref()
            .ok_or(GpuError::Device("no loss target set".into()))?;
        let n = b.width * b.height;
        let [main, forward, backward] = &b.uniforms;
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("loss"),
            timestamp_writes: None,
        });
        let mut run =
            |pipeline: &wgpu::ComputePipeline, entries: &[(u32, Bind<'_>)], threads: u32| {
                let group = kernel::bind_group(device, pipeline, entries);
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &group, &[]);
                kernel::dispatch(&mut pass, threads.div_ceil(kernel::WORKGROUP));
            };
        run(
            &self.prepare,
            &[
                (0, Bind::Buffer(main)),
                (3, Bind::Buffer(out_color)),
                (4, Bind::Buffer(&b.targets)),
                (5, Bind::Buffer(&b.planes)),
            ],
            n,
        );
        for (uniforms, planes, count) in [
            (forward, &b.planes, FORWARD_PLANES),
            (backward, &b.back, BACKWARD_PLANES),
        ] {
            if count == BACKWARD_PLANES {
                run(
                    &self.ssim_maps,
                    &[
                        (0, Bind::Buffer(main)),
                        (4, Bind::Buffer(&b.targets)),
                        (5, Bind::Buffer(&b.planes)),
                        (6, Bind::Buffer(&b.back)),
                        (7, Bind::Buffer(&b.partials)),
                    ],
                    n,
                );
            }
            run(
                &self.blur_h,
                &[
                    (0, Bind::Buffer(uniforms)),
                    (1, Bind::Buffer(planes)),
                    (2, Bind::Buffer(&b.tmp)),
                ],
                n * count,
            );
            run(
                &self.blur_v,
                &[
                    (0, Bind::Buffer(uniforms)),
                    (1, Bind::Buffer(&b.tmp)),
                    (2, Bind::Buffer(planes)),
                ],
                n * count,
            );
        }
        run(
            &self.combine,
            &[
                (0, Bind::Buffer(main)),
                (3, Bind::Buffer(out_color)),
                (4, Bind::Buffer(&b.targets)),
                (6, Bind::Buffer(&b.back)),
                (7, Bind::Buffer(&b.partials)),
                (8, Bind::Buffer(out_labels)),
                (9, Bind::Buffer(&b.label_targets)),
                (10, Bind::Buffer(v_pixels)),
            ],
            n,
        );
        Ok(())
    }

    /// The loss and its gradients for a frame given on the CPU (`rendered`: RGB interleaved,
    /// `rendered_labels`: `label_channels` per pixel): the stage alone, for tests and benches.
    /// Returns (loss, dL/d colour, dL/d labels).
    #[allow(clippy::too_many_arguments)]
    pub fn evaluate(
        &mut self,
        ctx: &GpuContext,
        width: u32,
        height: u32,
        rendered: &[f32],
        rendered_labels: &[f32],
        target: &LossTarget,
        weights: &LossWeights,
    ) -> Result<(f32, Vec<f32>, Vec<f32>), GpuError> {
        let n = width as usize * height as usize;
        let l = target.labels.len();
        if rendered.len() != n * 3 || rendered_labels.len() != n * l {
            return Err(GpuError::InvalidSplats("rendered frame size".into()));
        }
        self.set_target(ctx, width, height, l, target, weights)?;
        let device = &ctx.device;
        let none = wgpu::BufferUsages::empty();
        let rgba: Vec<f32> = rendered
            .chunks_exact(3)
            .flat_map(|c| [c[0], c[1], c[2], 1.0])
            .collect();
        let out_color = kernel::storage(device, "loss test colour", (n * 16) as u64, none);
        let out_labels = kernel::storage(device, "loss test labels", (n * l * 4) as u64, none);
        let stride = 5 + l;
        let v_pixels =
            kernel::storage(device, "loss test gradients", (n * stride * 4) as u64, none);
        ctx.queue
            .write_buffer(&out_color, 0, bytemuck::cast_slice(&rgba));
        if l > 0 {
            ctx.queue
                .write_buffer(&out_labels, 0, bytemuck::cast_slice(rendered_labels));
        }
        let mut encoder = device.create_command_encoder(&Default::default());
        self.encode(device, &mut encoder, &out_color, &out_labels, &v_pixels)?;
        ctx.queue.submit([encoder.finish()]);
        let packed = readback::read_f32(ctx, &v_pixels, n * stride)?;
        let mut v_color = Vec::with_capacity(n * 3);
        let mut v_labels = Vec::with_capacity(n * l);
        for cell in packed.chunks_exact(stride) {
            v_color.extend_from_slice(&cell[..3]);
            v_labels.extend_from_slice(&cell[5..]);
        }
        Ok((self.read_loss(ctx)?, v_color, v_labels))
    }

    /// The loss of the last encoded frame (blocking read of the partial sums).
    pub fn read_loss(&self, ctx: &GpuContext) -> Result<f32, GpuError> {
        let (Some(b), Some(w)) = (self.buffers.as_ref(), self.weights) else {
            return Err(GpuError::Readback("no loss computed".into()));
        };
        let groups = (b.width * b.height).div_ceil(kernel::WORKGROUP) as usize;
        let sums = readback::read_f32(ctx, &b.partials, groups * PARTIALS)?;
        let (mut ssim, mut l1, mut label) = (0.0f64, 0.0f64, 0.0f64);
        for s in sums.chunks_exact(PARTIALS) {
            ssim += s[0] as f64;
            l1 += s[1] as f64;
            label += s[2] as f64;
        }
        let lambda = w.ssim_lambda as f64;
        let photometric = if self.empty_region {
            0.0
        } else {
            (1.0 - lambda) * l1 + lambda * (1.0 - ssim)
        };
        Ok((w.rgb_weight as f64 * photometric + w.label_weight as f64 * label) as f32)
    }
}
