//! `GpuBackend` keeping the model on the GPU between steps ("resident" training): the trainer
//! uploads the model and Adam's moments after it changed them on the CPU, then each step renders
//! the uploaded model and runs the loss (`step_resident_with_loss`; or the CPU's loss from the
//! frame read back, `forward_resident` + `step_resident`), both backward kernels and Adam on the
//! GPU, reading back a 4-byte non-finite flag and the loss; it downloads the model, moments and
//! density statistics when density control, a checkpoint or a snapshot needs them.

use std::time::Instant;

use super::GpuBackend;
use crate::gpu::adam::{DensifyStats, GROUPS, GpuAdam, GroupStep, Moments};
use crate::gpu::loss::{GpuLoss, LossTarget, LossWeights};
use crate::gpu::{GpuError, GpuRenderSettings, readback};
use crate::raster::{PixelGrads, RenderOutput, RenderSettings};
use crate::scene::Camera;
use crate::splats::Splats;

impl GpuBackend {
    /// Uploads the model, Adam's moments (per group `(m, v)` in `train::adam`'s layout) and
    /// the frozen flags; density statistics start at zero.
    pub fn upload_resident(
        &mut self,
        splats: &Splats,
        moments: [(&[f32], &[f32]); GROUPS],
        frozen: &[bool],
    ) -> Result<(), GpuError> {
        let t = Instant::now();
        self.renderer.upload(splats)?;
        let ctx = self.renderer.context().clone();
        let adam = self.adam.get_or_insert_with(|| GpuAdam::new(&ctx));
        adam.upload(&ctx, self.renderer.splat_buffers(), moments, frozen)?;
        self.timings.project = t.elapsed();
        Ok(())
    }

    /// Renders the uploaded model from `camera` and reads the frame back.
    pub fn forward_resident(
        &mut self,
        camera: &Camera,
        settings: &RenderSettings,
        out: &mut RenderOutput,
    ) -> Result<(), GpuError> {
        self.timings.project = std::time::Duration::ZERO;
        self.render_and_read(camera, settings, out)
    }

    /// The backward of the last forward and one Adam step of the uploaded model, on the GPU;
    /// returns the non-finite bits (`GpuAdam::take_non_finite`: 0 when all is well).
    pub fn step_resident(
        &mut self,
        v_out: &PixelGrads,
        groups: &[GroupStep; GROUPS],
        betas: (f32, f32, f32),
    ) -> Result<u32, GpuError> {
        let t = Instant::now();
        self.upload_pixel_grads(v_out)?;
        let ctx = self.renderer.context().clone();
        let (Some(buffers), Some(adam), Some(forward)) = (
            self.buffers.as_ref(),
            self.adam.as_ref(),
            self.renderer.forward_state(),
        ) else {
            return Err(GpuError::Device(
                "a resident step needs an uploaded model and a forward first".into(),
            ));
        };
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.encode_backward_and_adam(&mut encoder, &forward, buffers, adam, groups, betas)?;
        ctx.queue.submit([encoder.finish()]);
        let bits = adam.take_non_finite(&ctx)?;
        // One submission: the whole backward and the optimiser are timed together.
        self.timings.raster_backward = t.elapsed();
        self.timings.project_backward = std::time::Duration::ZERO;
        Ok(bits)
    }

    /// A resident step whose loss is computed on the GPU too: render the uploaded model, the
    /// loss of `target` and its gradient into the backward's input, both backward kernels and
    /// Adam, in one submission; reads back only the non-finite bits and the loss's partial sums.
    /// Returns (loss, non-finite bits).
    #[allow(clippy::too_many_arguments)]
    pub fn step_resident_with_loss(
        &mut self,
        camera: &Camera,
        settings: &RenderSettings,
        target: &LossTarget,
        weights: &LossWeights,
        groups: &[GroupStep; GROUPS],
        betas: (f32, f32, f32),
    ) -> Result<(f32, u32), GpuError> {
        let t = Instant::now();
        self.renderer
            .render_blocking(camera, &GpuRenderSettings::from(settings))?;
        self.timings.raster_forward = t.elapsed();
        let t = Instant::now();
        let ctx = self.renderer.context().clone();
        let k = camera.intrinsics;
        let model = self.renderer.splat_buffers();
        let labels = model.label_channels();
        self.ensure_backward_buffers(k.width as usize * k.height as usize)?;
        self.loss
            .get_or_insert_with(|| GpuLoss::new(&ctx.device))
            .set_target(&ctx, k.width, k.height, labels, target, weights)?;
        let (Some(buffers), Some(adam), Some(loss), Some(forward)) = (
            self.buffers.as_ref(),
            self.adam.as_ref(),
            self.loss.as_ref(),
            self.renderer.forward_state(),
        ) else {
            return Err(GpuError::Device(
                "a resident step needs an uploaded model and a forward first".into(),
            ));
        };
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        loss.encode(
            &ctx.device,
            &mut encoder,
            forward.out_color,
            forward.out_labels,
            &buffers.v_pixels,
        )?;
        self.encode_backward_and_adam(&mut encoder, &forward, buffers, adam, groups, betas)?;
        ctx.queue.submit([encoder.finish()]);
        let bits = adam.take_non_finite(&ctx)?;
        let value = loss.read_loss(&ctx)?;
        self.timings.raster_backward = t.elapsed();
        self.timings.project_backward = std::time::Duration::ZERO;
        Ok((value, bits))
    }

    /// Records both backward kernels of the last forward and Adam's step of the uploaded model.
    fn encode_backward_and_adam(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        forward: &crate::gpu::renderer::ForwardState<'_>,
        buffers: &crate::gpu::backward::BackwardBuffers,
        adam: &GpuAdam,
        groups: &[GroupStep; GROUPS],
        betas: (f32, f32, f32),
    ) -> Result<(), GpuError> {
        let ctx = self.renderer.context();
        self.backward
            .encode_rasterize(&ctx.device, encoder, forward, buffers);
        self.backward
            .encode_project(&ctx.device, encoder, forward, buffers);
        adam.encode_step(
            ctx,
            encoder,
            self.renderer.splat_buffers(),
            buffers,
            groups,
            betas,
        )
    }

    /// Reads the uploaded model back into `splats` (same count and shape) and returns Adam's
    /// moments.
    pub fn download_resident(&mut self, splats: &mut Splats) -> Result<Moments, GpuError> {
        let ctx = self.renderer.context().clone();
        let model = self.renderer.splat_buffers();
        let n = model.len();
        if splats.len() != n || splats.label_channels != model.label_channels() {
            return Err(GpuError::InvalidSplats(format!(
                "downloading {n} Gaussians into a model of {}",
                splats.len()
            )));
        }
        let layout = model.layout();
        let geometry =
            readback::read_f32(&ctx, model.geometry(), layout.opacities_at as usize + n)?;
        let section = |at: u32, per: usize| &geometry[at as usize..at as usize + n * per];
        splats
            .means
            .copy_from_slice(bytemuck::cast_slice(section(0, 3)));
        splats
            .log_scales
            .copy_from_slice(bytemuck::cast_slice(section(layout.log_scales_at, 3)));
        // Element by element: a Quat may be 16-byte aligned, a slice of f32s is not.
        for (q, c) in splats
            .rotations
            .iter_mut()
            .zip(section(layout.rotations_at, 4).chunks_exact(4))
        {
            *q = glam::Quat::from_xyzw(c[0], c[1], c[2], c[3]);
        }
        splats
            .raw_opacities
            .copy_from_slice(section(layout.opacities_at, 1));
        let sh = readback::read_f32(&ctx, model.sh(), splats.sh.len())?;
        splats.sh.copy_from_slice(&sh);
        let labels = readback::read_f32(&ctx, model.raw_labels(), splats.raw_labels.len())?;
        splats.raw_labels.copy_from_slice(&labels);
        self.adam
            .as_ref()
            .ok_or(GpuError::Readback("no Adam state uploaded".into()))?
            .download(&ctx, model)
    }

    /// Density control's statistics since the last upload or take, zeroed after reading.
    pub fn take_densify_stats(&mut self) -> Result<DensifyStats, GpuError> {
        let ctx = self.renderer.context().clone();
        self.adam
            .as_mut()
            .ok_or(GpuError::Readback("no Adam state uploaded".into()))?
            .take_stats(&ctx)
    }
}

impl GpuBackend {
    /// One GPU-resident step (what `--backend gpu` trains with) timed stage by stage, each
    /// stage submitted and waited for on its own (wall-clock): the photo's upload, the forward
    /// kernels (GPU timestamps when the device has them), the loss, both backward kernels, Adam
    /// and the read-back of the flag and the loss. The model and zero moments are uploaded
    /// first (not timed: a run does that only after density control).
    pub fn profile_resident_step(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        target: &LossTarget,
        weights: &LossWeights,
    ) -> Result<super::StepProfile, GpuError> {
        let per = crate::gpu::adam::per_group_counts(splats);
        let zeros: Vec<Vec<f32>> = per.iter().map(|&k| vec![0.0; k * splats.len()]).collect();
        let moments: [(&[f32], &[f32]); GROUPS] =
            std::array::from_fn(|g| (zeros[g].as_slice(), zeros[g].as_slice()));
        let frozen = vec![false; splats.len()];
        self.upload_resident(splats, moments, &frozen)?;
        let groups = [GroupStep {
            step_size: 0.0,
            inv_bias2_sqrt: 1.0,
            on: true,
        }; GROUPS];
        let betas = (0.9, 0.999, 1e-15);
        // One untimed step so that every buffer fits.
        self.step_resident_with_loss(camera, settings, target, weights, &groups, betas)?;
        let ctx = self.renderer.context().clone();
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let mut stages = Vec::new();
        let k = camera.intrinsics;
        let labels = self.renderer.splat_buffers().label_channels();
        let t = Instant::now();
        let loss = self
            .loss
            .as_mut()
            .ok_or(GpuError::Device("loss stage missing".into()))?;
        loss.set_target(&ctx, k.width, k.height, labels, target, weights)?;
        ctx.wait_idle()?;
        stages.push(("upload_photo", ms(t)));
        let forward = self
            .renderer
            .render_timed(camera, &GpuRenderSettings::from(settings))?;
        stages.extend(forward.stages.iter().copied());
        let (Some(buffers), Some(adam), Some(loss), Some(state)) = (
            self.buffers.as_ref(),
            self.adam.as_ref(),
            self.loss.as_ref(),
            self.renderer.forward_state(),
        ) else {
            return Err(GpuError::Device("resident stages missing".into()));
        };
        let mut timed =
            |name: &'static str,
             record: &mut dyn FnMut(&mut wgpu::CommandEncoder) -> Result<(), GpuError>|
             -> Result<(), GpuError> {
                let t = Instant::now();
                let mut encoder = ctx.device.create_command_encoder(&Default::default());
                record(&mut encoder)?;
                ctx.queue.submit([encoder.finish()]);
                ctx.wait_idle()?;
                stages.push((name, ms(t)));
                Ok(())
            };
        timed("loss", &mut |e| {
            loss.encode(
                &ctx.device,
                e,
                state.out_color,
                state.out_labels,
                &buffers.v_pixels,
            )
        })?;
        timed("rasterize_backward", &mut |e| {
            self.backward
                .encode_rasterize(&ctx.device, e, &state, buffers);
            Ok(())
        })?;
        timed("project_backward", &mut |e| {
            self.backward
                .encode_project(&ctx.device, e, &state, buffers);
            Ok(())
        })?;
        timed("adam", &mut |e| {
            adam.encode_step(
                &ctx,
                e,
                self.renderer.splat_buffers(),
                buffers,
                &groups,
                betas,
            )
        })?;
        let t = Instant::now();
        adam.take_non_finite(&ctx)?;
        loss.read_loss(&ctx)?;
        stages.push(("read_flag_and_loss", ms(t)));
        Ok(super::StepProfile {
            forward_source: forward.source,
            stages,
            intersections: forward.intersections,
        })
    }
}
