//! The GPU as the trainer's renderer: [`RasterBackend`] over [`GpuRenderer`] and the backward
//! kernels. Per step it uploads the model, renders, reads the frame back for the loss (on the
//! CPU), uploads the pixel gradients, runs both backward kernels and reads the parameter
//! gradients back; Adam and density control stay on the CPU. A GPU failure does not panic: the
//! step's outputs are zero and [`RasterBackend::fault`] names it, which ends the run.

use std::time::Instant;

use super::backward::{BackwardBuffers, BackwardStage, PARAM_FLOATS, PIXEL_FLOATS};
use super::{GpuContext, GpuError, GpuRenderSettings, GpuRenderer, readback};
use crate::raster::{
    PixelGrads, RasterBackend, RenderOutput, RenderSettings, SplatGrads, StageTimings,
};
use crate::scene::Camera;
use crate::splats::Splats;

pub struct GpuBackend {
    renderer: GpuRenderer,
    backward: BackwardStage,
    buffers: Option<BackwardBuffers>,
    /// Pixel gradients packed for upload (stride `PIXEL_FLOATS` + label channels).
    packed: Vec<f32>,
    radii: Vec<u32>,
    timings: StageTimings,
    fault: Option<String>,
    /// Adam's moments on the GPU, once the trainer keeps the model here (`resident`).
    adam: Option<super::adam::GpuAdam>,
    /// The loss on the GPU (resident steps that compute it there).
    loss: Option<super::loss::GpuLoss>,
}

mod resident;

impl GpuBackend {
    /// Float atomics accumulate the gradients where the device has them, a compare-and-swap
    /// loop otherwise.
    pub fn new(ctx: &GpuContext) -> Result<GpuBackend, GpuError> {
        GpuBackend::with_accumulation(ctx, ctx.capabilities.float32_atomics)
    }

    /// `new`, choosing the accumulation (tests run both on one device).
    pub fn with_accumulation(
        ctx: &GpuContext,
        float_atomics: bool,
    ) -> Result<GpuBackend, GpuError> {
        if float_atomics && !ctx.capabilities.float32_atomics {
            return Err(GpuError::Device(
                "this device has no float atomics (SHADER_FLOAT32_ATOMIC)".into(),
            ));
        }
        Ok(GpuBackend {
            renderer: GpuRenderer::new(ctx)?,
            backward: BackwardStage::new(&ctx.device, float_atomics),
            buffers: None,
            packed: Vec::new(),
            radii: Vec::new(),
            timings: StageTimings::default(),
            fault: None,
            adam: None,
            loss: None,
        })
    }

    /// The adapter and how gradients are accumulated, for logs.
    pub fn describe(&self) -> String {
        let how = if self.backward.float_atomics() {
            "float atomics"
        } else {
            "compare-and-swap"
        };
        format!("{}, {how}", self.renderer.context().describe())
    }

    pub fn renderer(&self) -> &GpuRenderer {
        &self.renderer
    }

    fn try_forward(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        out: &mut RenderOutput,
    ) -> Result<(), GpuError> {
        let t = Instant::now();
        self.renderer.upload(splats)?;
        self.timings.project = t.elapsed();
        self.render_and_read(camera, settings, out)
    }

    /// Renders the uploaded model and reads the frame back into `out`.
    pub(super) fn render_and_read(
        &mut self,
        camera: &Camera,
        settings: &RenderSettings,
        out: &mut RenderOutput,
    ) -> Result<(), GpuError> {
        let t = Instant::now();
        self.renderer
            .render_blocking(camera, &GpuRenderSettings::from(settings))?;
        let frame = self.renderer.read_frame()?;
        out.width = frame.width;
        out.height = frame.height;
        out.label_channels = frame.label_channels;
        out.color = frame.color;
        out.alpha = frame.alpha;
        out.depth = frame.depth;
        out.labels = frame.labels;
        self.timings.raster_forward = t.elapsed();
        Ok(())
    }

    fn try_backward(
        &mut self,
        splats: &Splats,
        v_out: &PixelGrads,
        grads: &mut SplatGrads,
    ) -> Result<(), GpuError> {
        let t = Instant::now();
        let ctx = self.renderer.context().clone();
        let n = splats.len();
        let l = splats.label_channels;
        let sh_floats = splats.sh_coeffs() * 3;
        self.upload_pixel_grads(v_out)?;
        let buffers = self
            .buffers
            .as_ref()
            .ok_or(GpuError::Device("backward buffers missing".into()))?;
        let forward = self
            .renderer
            .forward_state()
            .ok_or(GpuError::Readback("backward before any forward".into()))?;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.backward
            .encode_rasterize(&ctx.device, &mut encoder, &forward, buffers);
        ctx.queue.submit([encoder.finish()]);
        ctx.wait_idle()?;
        self.timings.raster_backward = t.elapsed();

        let t = Instant::now();
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.backward
            .encode_project(&ctx.device, &mut encoder, &forward, buffers);
        ctx.queue.submit([encoder.finish()]);
        let params = readback::read_f32(&ctx, &buffers.param_grads, n * PARAM_FLOATS)?;
        let v_sh = readback::read_f32(&ctx, &buffers.v_sh, n * sh_floats)?;
        let v_raw_labels = readback::read_f32(&ctx, &buffers.v_raw_labels, n * l)?;
        grads.reset(splats);
        self.radii.clear();
        for (g, p) in params.chunks_exact(PARAM_FLOATS).enumerate() {
            grads.v_means[g] = glam::Vec3::new(p[0], p[1], p[2]);
            grads.v_log_scales[g] = glam::Vec3::new(p[3], p[4], p[5]);
            grads.v_rotations[g] = glam::Vec4::new(p[6], p[7], p[8], p[9]);
            grads.v_raw_opacities[g] = p[10];
            grads.v_means2d_norm[g] = p[11];
            let radius = p[12].to_bits();
            grads.visible[g] = radius > 0;
            self.radii.push(radius);
        }
        grads.v_sh.copy_from_slice(&v_sh);
        grads.v_raw_labels.copy_from_slice(&v_raw_labels);
        self.timings.project_backward = t.elapsed();
        Ok(())
    }

    /// Packs and uploads the pixel gradients, sizing the backward buffers for the uploaded model.
    pub(super) fn upload_pixel_grads(&mut self, v_out: &PixelGrads) -> Result<(), GpuError> {
        let ctx = self.renderer.context().clone();
        let l = self.renderer.splat_buffers().label_channels();
        let pixels = v_out.color.len() / 3;
        self.ensure_backward_buffers(pixels)?;
        let stride = PIXEL_FLOATS + l;
        self.packed.clear();
        self.packed.resize(pixels * stride, 0.0);
        for (p, cell) in self.packed.chunks_exact_mut(stride).enumerate() {
            cell[..3].copy_from_slice(&v_out.color[p * 3..p * 3 + 3]);
            cell[3] = v_out.alpha.map_or(0.0, |a| a[p]);
            cell[4] = v_out.depth.map_or(0.0, |d| d[p]);
            if let Some(labels) = v_out.labels {
                cell[PIXEL_FLOATS..].copy_from_slice(&labels[p * l..(p + 1) * l]);
            }
        }
        let buffers = self
            .buffers
            .as_ref()
            .ok_or(GpuError::Device("backward buffers missing".into()))?;
        ctx.queue
            .write_buffer(&buffers.v_pixels, 0, bytemuck::cast_slice(&self.packed));
        Ok(())
    }

    /// Sizes the backward's buffers for the uploaded model and a `pixels`-pixel frame.
    pub(super) fn ensure_backward_buffers(&mut self, pixels: usize) -> Result<(), GpuError> {
        let model = self.renderer.splat_buffers();
        let l = model.label_channels();
        let sh_floats = crate::splats::model::sh_coeffs_for_degree(model.sh_degree()) * 3;
        let capacity = model.capacity().max(1);
        if !self
            .buffers
            .as_ref()
            .is_some_and(|b| b.fits(capacity, pixels, l, sh_floats))
        {
            let device = &self.renderer.context().device;
            self.buffers = Some(BackwardBuffers::new(device, capacity, pixels, l, sh_floats));
        }
        Ok(())
    }
}

/// Milliseconds per stage of one training step's renderer work on the GPU (the bench).
#[derive(Clone, Debug, serde::Serialize)]
pub struct StepProfile {
    /// How the forward kernels were timed: "gpu-timestamps" or "wall-clock" (submit and wait
    /// per stage). The backward kernels and the transfers are wall-clock, submit to completion.
    pub forward_source: &'static str,
    pub stages: Vec<(&'static str, f64)>,
    pub intersections: u32,
}

impl GpuBackend {
    /// One step's renderer work timed stage by stage: the model's upload, every forward kernel,
    /// the frame's read-back, the pixel gradients' upload, the two backward kernels and the
    /// gradients' read-back. Runs one untimed step first so that buffers already fit.
    pub fn profile_step(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        v_out: &PixelGrads,
    ) -> Result<StepProfile, GpuError> {
        let mut out = RenderOutput::default();
        let mut grads = SplatGrads::zeros(splats);
        self.try_forward(splats, camera, settings, &mut out)?;
        self.try_backward(splats, v_out, &mut grads)?;
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let ctx = self.renderer.context().clone();
        let mut stages = Vec::new();

        let t = Instant::now();
        self.renderer.upload(splats)?;
        ctx.wait_idle()?;
        stages.push(("upload_model", ms(t)));
        let gpu_settings = GpuRenderSettings::from(settings);
        let forward = self.renderer.render_timed(camera, &gpu_settings)?;
        stages.extend(forward.stages.iter().copied());
        let t = Instant::now();
        self.renderer.read_frame()?;
        stages.push(("read_frame", ms(t)));

        let buffers = self
            .buffers
            .as_ref()
            .ok_or(GpuError::Device("backward buffers missing".into()))?;
        let t = Instant::now();
        ctx.queue
            .write_buffer(&buffers.v_pixels, 0, bytemuck::cast_slice(&self.packed));
        ctx.wait_idle()?;
        stages.push(("upload_pixel_grads", ms(t)));
        let state = self
            .renderer
            .forward_state()
            .ok_or(GpuError::Readback("nothing rendered".into()))?;
        let t = Instant::now();
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.backward
            .encode_rasterize(&ctx.device, &mut encoder, &state, buffers);
        ctx.queue.submit([encoder.finish()]);
        ctx.wait_idle()?;
        stages.push(("rasterize_backward", ms(t)));
        let t = Instant::now();
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.backward
            .encode_project(&ctx.device, &mut encoder, &state, buffers);
        ctx.queue.submit([encoder.finish()]);
        ctx.wait_idle()?;
        stages.push(("project_backward", ms(t)));
        let n = splats.len();
        let t = Instant::now();
        readback::read_f32(&ctx, &buffers.param_grads, n * PARAM_FLOATS)?;
        readback::read_f32(&ctx, &buffers.v_sh, n * splats.sh_coeffs() * 3)?;
        readback::read_f32(&ctx, &buffers.v_raw_labels, n * splats.label_channels)?;
        stages.push(("read_grads", ms(t)));
        Ok(StepProfile {
            forward_source: forward.source,
            stages,
            intersections: forward.intersections,
        })
    }
}

impl RasterBackend for GpuBackend {
    fn name(&self) -> &'static str {
        "gpu"
    }

    fn forward(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        out: &mut RenderOutput,
    ) {
        if let Err(e) = self.try_forward(splats, camera, settings, out) {
            self.fault.get_or_insert(format!("GPU forward failed: {e}"));
            let k = camera.intrinsics;
            let pixels = (k.width * k.height) as usize;
            out.width = k.width;
            out.height = k.height;
            out.label_channels = splats.label_channels;
            out.color = vec![0.0; pixels * 3];
            out.alpha = vec![0.0; pixels];
            out.depth = vec![0.0; pixels];
            out.labels = vec![0.0; pixels * splats.label_channels];
        }
    }

    fn backward(
        &mut self,
        splats: &Splats,
        _camera: &Camera,
        _settings: &RenderSettings,
        v_out: &PixelGrads,
        grads: &mut SplatGrads,
    ) {
        if let Err(e) = self.try_backward(splats, v_out, grads) {
            self.fault
                .get_or_insert(format!("GPU backward failed: {e}"));
            grads.reset(splats);
            self.radii.clear();
            self.radii.resize(splats.len(), 0);
        }
    }

    /// Per Gaussian the radius of the last forward, as its backward read it back (the trainer
    /// reads radii after the backward).
    fn radii(&self) -> &[u32] {
        &self.radii
    }

    /// `project`: the model upload; `raster_forward`: the forward kernels and the frame's
    /// read-back; `raster_backward`: the pixel gradients' upload and the rasterize backward;
    /// `project_backward`: the projection backward and the gradients' read-back.
    fn timings(&self) -> StageTimings {
        self.timings
    }

    fn fault(&self) -> Option<&str> {
        self.fault.as_deref()
    }

    fn as_any_mut(&mut self) -> Option<&mut dyn std::any::Any> {
        Some(self)
    }
}
