//! `GpuRenderer`: "render these splats with this camera" on the GPU. Owns the splat buffers, the
//! per-frame scratch and the stages, records the whole forward pass into a caller's encoder
//! (viewer) or renders to CPU images (tests, CLI). No kernel code, no UI code.

use super::count_probe::CountProbe;
use super::emit::{EmitBuffers, EmitStage};
use super::frame_buffers::{FrameBuffers, IsectBuffers};
use super::kernel;
use super::prefix_sum::PrefixSum;
use super::project::{FrameUniforms, ProjectOutputs, ProjectStage, tile_bounds};
use super::radix_sort::{RadixSort, SortedIn, bits_for};
use super::rasterize::{RasterBuffers, RasterizeStage};
use super::render_settings::GpuRenderSettings;
use super::splat_buffers::SplatBuffers;
use super::tile_ranges::TileRangesStage;
use super::timing::Stage;
use super::{GpuContext, GpuError, readback};
use crate::scene::{Camera, RgbImage};
use crate::splats::Splats;

mod stages;

/// A rendered frame read back to the CPU (same channels and conventions as `raster::RenderOutput`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GpuFrame {
    pub width: u32,
    pub height: u32,
    /// RGB interleaved, composited on the background.
    pub color: Vec<f32>,
    /// `1 - T_final`.
    pub alpha: Vec<f32>,
    /// `Σ z_i α_i T_i` (not normalised).
    pub depth: Vec<f32>,
    /// `[pixel * label_channels + k] = Σ sigmoid(raw_label_ik) α_i T_i`.
    pub labels: Vec<f32>,
    pub label_channels: usize,
}

impl GpuFrame {
    pub fn to_rgb_image(&self) -> RgbImage {
        RgbImage {
            width: self.width,
            height: self.height,
            data: self.color.clone(),
        }
    }
}

/// Milliseconds per stage of one frame.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StageTimings {
    /// "gpu-timestamps" or "wall-clock" (submit and wait per stage: includes driver overhead).
    pub source: &'static str,
    pub stages: Vec<(&'static str, f64)>,
    /// Wall time of the whole frame, submit to completion.
    pub total_ms: f64,
    pub intersections: u32,
}

/// What `prepare` settled for the frame being recorded.
#[derive(Clone, Copy, Debug)]
struct FramePlan {
    num_gaussians: u32,
    tile_bounds: [u32; 2],
    tile_bits: u32,
}

/// What the last forward left on the GPU, for the backward kernels to replay.
pub(super) struct ForwardState<'a> {
    pub(super) uniforms: &'a wgpu::Buffer,
    pub(super) ranges: &'a wgpu::Buffer,
    /// Gaussian ids of the sorted intersections.
    pub(super) isect_gids: &'a wgpu::Buffer,
    pub(super) projected: &'a wgpu::Buffer,
    pub(super) labels: &'a wgpu::Buffer,
    pub(super) out_state: &'a wgpu::Buffer,
    /// The frame: colour + alpha, depth, label channels.
    pub(super) out_color: &'a wgpu::Buffer,
    pub(super) out_depth: &'a wgpu::Buffer,
    pub(super) out_labels: &'a wgpu::Buffer,
    pub(super) geometry: &'a wgpu::Buffer,
    pub(super) sh: &'a wgpu::Buffer,
    pub(super) tile_bounds: [u32; 2],
    pub(super) num_gaussians: u32,
}

/// The GPU forward pass over one uploaded model.
pub struct GpuRenderer {
    ctx: GpuContext,
    splats: SplatBuffers,
    project: ProjectStage,
    emit: EmitStage,
    tile_ranges: TileRangesStage,
    rasterize: RasterizeStage,
    depth_sort: RadixSort,
    scan: PrefixSum,
    isect: IsectBuffers,
    frame: Option<FrameBuffers>,
    isect_count: wgpu::Buffer,
    depth_count: wgpu::Buffer,
    probe: CountProbe,
    plan: Option<FramePlan>,
    output_generation: u64,
}

/// Intersections per Gaussian assumed before the first frame reports the real total.
const INITIAL_ISECTS_PER_GAUSSIAN: u32 = 8;
const MIN_ISECT_CAPACITY: u32 = 1 << 16;

impl GpuRenderer {
    /// Compiles every pipeline once; buffers start empty.
    pub fn new(ctx: &GpuContext) -> Result<GpuRenderer, GpuError> {
        let device = &ctx.device;
        let depth_sort = RadixSort::new(device, 1);
        let isect = IsectBuffers::new(device, &depth_sort, MIN_ISECT_CAPACITY);
        Ok(GpuRenderer {
            splats: SplatBuffers::new(ctx),
            project: ProjectStage::new(device),
            emit: EmitStage::new(device),
            tile_ranges: TileRangesStage::new(device),
            rasterize: RasterizeStage::new(device),
            scan: PrefixSum::new(device, 1),
            depth_sort,
            isect,
            frame: None,
            isect_count: kernel::storage(device, "isect_count", 4, wgpu::BufferUsages::empty()),
            depth_count: kernel::storage(device, "depth_count", 4, wgpu::BufferUsages::empty()),
            probe: CountProbe::new(device),
            plan: None,
            output_generation: 0,
            ctx: ctx.clone(),
        })
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// Replaces the model (in place when it fits; see [`SplatBuffers::upload`]).
    pub fn upload(&mut self, splats: &Splats) -> Result<(), GpuError> {
        self.splats.upload(&self.ctx, splats)
    }

    /// Rewrites Gaussians `range` of a model with the uploaded count and shape.
    pub fn patch(
        &mut self,
        splats: &Splats,
        range: std::ops::Range<usize>,
    ) -> Result<(), GpuError> {
        self.splats.patch(&self.ctx, splats, range)
    }

    pub fn splat_buffers(&self) -> &SplatBuffers {
        &self.splats
    }

    /// The display texture of the last `render` (Rgba8Unorm, RGB composited, A = alpha).
    pub fn output_texture(&self) -> Option<&wgpu::Texture> {
        self.frame.as_ref().map(|f| &f.texture)
    }

    /// Bumps whenever the output texture is re-created (callers re-register it).
    pub fn output_generation(&self) -> u64 {
        self.output_generation
    }

    /// Room for tile/Gaussian intersections per frame (grows from the observed totals).
    pub fn intersection_capacity(&self) -> u32 {
        self.isect.capacity
    }

    fn isect_limit(&self) -> u32 {
        let words = self
            .ctx
            .limits
            .max_storage_buffer_binding_size
            .min(self.ctx.limits.max_buffer_size)
            / 4;
        words.min(u32::MAX as u64) as u32
    }

    fn grow_intersections(&mut self, total: u32) {
        if total <= self.isect.capacity {
            return;
        }
        let limit = self.isect_limit();
        if total > limit {
            tracing::warn!(
                total,
                limit,
                "more tile intersections than one GPU buffer holds; some splats are dropped"
            );
        }
        let wanted = (total as u64 * 5 / 4).min(limit as u64) as u32;
        if wanted > self.isect.capacity {
            self.isect = IsectBuffers::new(&self.ctx.device, &self.isect.tile_sort, wanted);
        }
    }

    /// Sizes the scratch for this frame and writes its uniforms and host-known lengths.
    fn prepare(
        &mut self,
        camera: &Camera,
        settings: &GpuRenderSettings,
    ) -> Result<FramePlan, GpuError> {
        let k = camera.intrinsics;
        if k.width == 0 || k.height == 0 || !(k.fx > 0.0 && k.fy > 0.0) {
            return Err(GpuError::InvalidCamera(format!(
                "image {}×{} with focal lengths ({}, {})",
                k.width, k.height, k.fx, k.fy
            )));
        }
        let device = &self.ctx.device;
        let capacity = self.splats.capacity().max(1);
        let n = self.splats.len() as u32;
        if (self.depth_sort.capacity() as usize) < capacity {
            self.depth_sort = self.depth_sort.resized(device, capacity as u32);
            self.scan = self.scan.resized(device, capacity as u32);
        }
        let labels = self.splats.label_channels();
        let fits = self.frame.as_ref().is_some_and(|f| {
            f.gaussian_capacity >= capacity
                && f.width == k.width
                && f.height == k.height
                && f.label_channels == labels
        });
        if !fits {
            self.frame = Some(FrameBuffers::new(
                device, capacity, k.width, k.height, labels,
            ));
            self.output_generation += 1;
        }
        // Before any total was observed, assume a few tiles per Gaussian; frames then correct it.
        let guess = n.saturating_mul(INITIAL_ISECTS_PER_GAUSSIAN);
        if guess > self.isect.capacity && self.plan.is_none() {
            self.grow_intersections(guess);
        }
        let frame = self
            .frame
            .as_ref()
            .ok_or(GpuError::Device("frame buffers missing".into()))?;
        let uniforms = FrameUniforms::new(camera, settings, &self.splats, self.isect.capacity);
        let q = &self.ctx.queue;
        q.write_buffer(&frame.uniforms, 0, bytemuck::bytes_of(&uniforms));
        q.write_buffer(&self.depth_count, 0, bytemuck::bytes_of(&n));
        self.scan.write_len(q, n);
        let tb = tile_bounds(k.width, k.height);
        let plan = FramePlan {
            num_gaussians: n,
            tile_bounds: tb,
            tile_bits: bits_for((tb[0] * tb[1]).saturating_sub(1)).max(1),
        };
        self.plan = Some(plan);
        Ok(plan)
    }

    /// Sorted tile keys and Gaussian ids after the tile sort.
    fn sorted_isects(&self, plan: &FramePlan) -> (&wgpu::Buffer, &wgpu::Buffer) {
        match RadixSort::result_location(plan.tile_bits) {
            SortedIn::Input => (&self.isect.tile_keys, &self.isect.isect_gids),
            SortedIn::Scratch => (
                self.isect.tile_sort.scratch_keys(),
                self.isect.tile_sort.scratch_values(),
            ),
        }
    }

    fn encode_stage(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        stage: Stage,
        plan: &FramePlan,
        timestamp_writes: Option<wgpu::ComputePassTimestampWrites<'_>>,
    ) {
        let Some(frame) = self.frame.as_ref() else {
            return;
        };
        let device = &self.ctx.device;
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(stage.name()),
            timestamp_writes,
        });
        let n = plan.num_gaussians;
        // Depth keys are 32 bits: 8 passes, an even number, so the sorted ids are back in depth_gids.
        let emit_buffers = EmitBuffers {
            uniforms: &frame.uniforms,
            projected: &frame.projected,
            sorted_gids: &frame.depth_gids,
            offsets: &frame.offsets,
            tile_keys: &self.isect.tile_keys,
            isect_gids: &self.isect.isect_gids,
            isect_count: &self.isect_count,
        };
        match stage {
            Stage::Project => self.project.encode(
                device,
                &mut pass,
                &frame.uniforms,
                &self.splats,
                &ProjectOutputs {
                    projected: &frame.projected,
                    depth_keys: &frame.depth_keys,
                    depth_gids: &frame.depth_gids,
                    labels: &frame.labels,
                },
            ),
            Stage::DepthSort => {
                let at = self.depth_sort.encode(
                    device,
                    &mut pass,
                    &frame.depth_keys,
                    &frame.depth_gids,
                    &self.depth_count,
                    32,
                );
                debug_assert_eq!(at, SortedIn::Input);
            }
            Stage::Offsets => {
                self.emit
                    .encode_offsets(device, &mut pass, &self.scan, &emit_buffers, n)
            }
            Stage::Emit => self.emit.encode_emit(device, &mut pass, &emit_buffers, n),
            Stage::TileSort => {
                self.isect.tile_sort.encode(
                    device,
                    &mut pass,
                    &self.isect.tile_keys,
                    &self.isect.isect_gids,
                    &self.isect_count,
                    plan.tile_bits,
                );
            }
            Stage::TileRanges => {
                let (keys, _) = self.sorted_isects(plan);
                self.tile_ranges.encode(
                    device,
                    &mut pass,
                    &frame.uniforms,
                    self.isect.tile_sort.sizes(),
                    self.isect.tile_sort.dispatch_args(),
                    keys,
                    &frame.ranges,
                    plan.tile_bounds[0] * plan.tile_bounds[1],
                );
            }
            Stage::Rasterize => {
                let (_, gids) = self.sorted_isects(plan);
                self.rasterize.encode(
                    device,
                    &mut pass,
                    &RasterBuffers {
                        uniforms: &frame.uniforms,
                        ranges: &frame.ranges,
                        isect_gids: gids,
                        projected: &frame.projected,
                        labels: &frame.labels,
                        out_color: &frame.out_color,
                        out_depth: &frame.out_depth,
                        out_labels: &frame.out_labels,
                        out_texture: &frame.view,
                        out_state: &frame.out_state,
                    },
                    plan.tile_bounds,
                );
            }
        }
    }

    /// Records the forward pass into `encoder`; returns the display texture's view. No
    /// read-back and no submit: the intersection total reaches the CPU a frame or two later
    /// and only grows the buffers (a frame that overflowed drops some intersections). Submit
    /// the encoder before the next call.
    pub fn render(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        camera: &Camera,
        settings: &GpuRenderSettings,
    ) -> Result<&wgpu::TextureView, GpuError> {
        if let Some(total) = self.probe.poll(&self.ctx.device) {
            self.grow_intersections(total);
        }
        let plan = self.prepare(camera, settings)?;
        encoder.clear_buffer(&self.isect_count, 0, None);
        for stage in Stage::ALL {
            self.encode_stage(encoder, stage, &plan, None);
        }
        self.probe.record_copy(encoder, &self.isect_count);
        self.frame
            .as_ref()
            .map(|f| &f.view)
            .ok_or(GpuError::Device("frame buffers missing".into()))
    }

    /// Renders, submits and waits; when the frame had more intersections than room, grows the
    /// buffers and renders again, so the result is exact. Returns the intersection total.
    pub fn render_blocking(
        &mut self,
        camera: &Camera,
        settings: &GpuRenderSettings,
    ) -> Result<u32, GpuError> {
        for _ in 0..2 {
            let plan = self.prepare(camera, settings)?;
            let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
            encoder.clear_buffer(&self.isect_count, 0, None);
            for stage in Stage::ALL {
                self.encode_stage(&mut encoder, stage, &plan, None);
            }
            self.ctx.queue.submit([encoder.finish()]);
            let total = self.read_intersection_count()?;
            if total <= self.isect.capacity {
                return Ok(total);
            }
            self.grow_intersections(total);
        }
        self.read_intersection_count()
    }

    /// Blocking render to CPU buffers (tests, CLI).
    pub fn render_to_image(
        &mut self,
        camera: &Camera,
        settings: &GpuRenderSettings,
    ) -> Result<GpuFrame, GpuError> {
        self.render_blocking(camera, settings)?;
        self.read_frame()
    }

    /// The last frame's buffers for the backward, the GPU loss and the selection pass (None
    /// before the first frame).
    pub(super) fn forward_state(&self) -> Option<ForwardState<'_>> {
        let frame = self.frame.as_ref()?;
        let plan = self.plan.as_ref()?;
        let (_, isect_gids) = self.sorted_isects(plan);
        Some(ForwardState {
            uniforms: &frame.uniforms,
            ranges: &frame.ranges,
            isect_gids,
            projected: &frame.projected,
            labels: &frame.labels,
            out_state: &frame.out_state,
            out_color: &frame.out_color,
            out_depth: &frame.out_depth,
            out_labels: &frame.out_labels,
            geometry: self.splats.geometry(),
            sh: self.splats.sh(),
            tile_bounds: plan.tile_bounds,
            num_gaussians: plan.num_gaussians,
        })
    }

    /// The last frame's buffers, for reading back.
    fn last_frame(&self) -> Result<&FrameBuffers, GpuError> {
        self.frame
            .as_ref()
            .ok_or(GpuError::Readback("nothing rendered yet".into()))
    }

    /// Reads the last frame's outputs back.
    pub fn read_frame(&self) -> Result<GpuFrame, GpuError> {
        let frame = self.last_frame()?;
        let pixels = frame.width as usize * frame.height as usize;
        let rgba = readback::read_f32(&self.ctx, &frame.out_color, pixels * 4)?;
        let mut color = Vec::with_capacity(pixels * 3);
        let mut alpha = Vec::with_capacity(pixels);
        for p in rgba.chunks_exact(4) {
            color.extend_from_slice(&p[..3]);
            alpha.push(p[3]);
        }
        Ok(GpuFrame {
            width: frame.width,
            height: frame.height,
            color,
            alpha,
            depth: readback::read_f32(&self.ctx, &frame.out_depth, pixels)?,
            labels: readback::read_f32(
                &self.ctx,
                &frame.out_labels,
                pixels * frame.label_channels,
            )?,
            label_channels: frame.label_channels,
        })
    }
}
