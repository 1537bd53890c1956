//! GPU-resident steps: with the GPU backend the model and Adam's moments stay on the device
//! between syncs. A step renders the uploaded model, computes the loss on the CPU from the frame
//! (the trainer's own loss code), then runs the backward kernels and Adam on the GPU and reads
//! back only a non-finite flag. The CPU model, moments and density statistics are brought up to
//! date (synced) when density control, importance pruning or a checkpoint is due, at the end,
//! and when a caller asks (`Trainer::sync`: snapshots, evaluation); whatever the CPU then
//! changes is uploaded before the next step. The schedule, the loss, density control, the
//! rollback and the checkpoints are the CPU step's; per-step clamps the GPU does not do (the
//! scale cap) and the per-photo light (folded into the colours every 100 steps) keep a run on
//! the per-step path (`GpuBackend` as a plain `RasterBackend`).

use std::time::Instant;

use super::{CHECKPOINT_EVERY, StepReport, Trainer};
use crate::gpu::adam::{GROUPS, GroupStep};
use crate::gpu::loss::{LossTarget, LossWeights};
use crate::gpu::{GpuBackend, GpuError};
use crate::raster::MAX_LABEL_CHANNELS;
use crate::raster::{PixelGrads, RasterBackend, RenderSettings};
use crate::train::adam::ParamGroup;
use crate::train::ssim::gaussian_window;

/// Where a GPU-resident run stands.
pub(super) struct Resident {
    /// The CPU model or moments changed since the last upload (start, density control,
    /// rollback, the label loss's detachment).
    pub(super) dirty: bool,
    /// The GPU model moved since the last download.
    stale: bool,
    /// The first GPU error (the run must end).
    fault: Option<String>,
    /// The loss too is computed on the GPU (off: the frame comes back for the CPU's loss).
    loss_on_gpu: bool,
}

impl Resident {
    pub(super) fn new() -> Resident {
        Resident {
            dirty: true,
            stale: false,
            fault: None,
            loss_on_gpu: true,
        }
    }

    pub(super) fn fault(&self) -> Option<&str> {
        self.fault.as_deref()
    }
}

fn gpu_of(backend: &mut Box<dyn RasterBackend>) -> Result<&mut GpuBackend, GpuError> {
    backend
        .as_any_mut()
        .and_then(|any| any.downcast_mut::<GpuBackend>())
        .ok_or(GpuError::Device(
            "the resident step needs the GPU backend".into(),
        ))
}

/// Whether a run of `spec` on `backend` can keep its model on the GPU.
pub(super) fn can_be_resident(
    spec: &crate::train::spec::TrainSpec,
    backend: &mut Box<dyn RasterBackend>,
) -> bool {
    gpu_of(backend).is_ok()
        && spec.max_scale_growth.is_none()
        && spec.appearance.is_none()
        && spec.geometry_rate.is_none()
}

/// What the Adam kernel's non-finite bits say (bit g: a gradient of group g, bit 8 + g: a
/// parameter it wrote), as the CPU optimiser words it.
fn non_finite_reason(bits: u32) -> String {
    let group = ParamGroup::ALL[(bits.trailing_zeros() % 8) as usize];
    if bits & 0xff != 0 {
        format!("gradient of {} is not finite", group.name())
    } else {
        format!("{} became non-finite", group.name())
    }
}

impl Trainer {
    /// Whether the model lives on the GPU between syncs.
    pub fn is_gpu_resident(&self) -> bool {
        self.resident.is_some()
    }

    /// Keeps the model on the CPU and moves it every step even on the GPU backend (the
    /// per-step path: for comparisons). Syncs first.
    pub fn leave_gpu_resident(&mut self) {
        self.sync();
        self.resident = None;
    }

    /// Computes the loss on the CPU from the frame read back each step, as the per-step path
    /// does, with the model, the backward and Adam still on the GPU (for comparisons).
    pub fn compute_loss_on_cpu(&mut self) {
        if let Some(r) = &mut self.resident {
            r.loss_on_gpu = false;
        }
    }

    /// Brings the CPU model (`splats()`), Adam's moments and the density statistics up to date
    /// with the GPU in a GPU-resident run; nothing otherwise. A GPU error is kept as the
    /// renderer's fault.
    pub fn sync(&mut self) {
        if let Err(e) = self.try_sync() {
            self.note_gpu_fault(e);
        }
    }

    fn note_gpu_fault(&mut self, e: GpuError) {
        if let Some(r) = &mut self.resident {
            r.fault.get_or_insert(format!("GPU: {e}"));
        }
    }

    fn try_sync(&mut self) -> Result<(), GpuError> {
        if !self.resident.as_ref().is_some_and(|r| r.stale) {
            return Ok(());
        }
        let gpu = gpu_of(&mut self.rasterizer)?;
        let moments = gpu.download_resident(&mut self.splats)?;
        let stats = gpu.take_densify_stats()?;
        for ((m, v), group) in moments.into_iter().zip(ParamGroup::ALL) {
            self.adam
                .set_moments(group, m, v)
                .map_err(GpuError::InvalidSplats)?;
        }
        if let Some(densifier) = &mut self.densifier {
            densifier.add_stats(&stats.grad_accum, &stats.visible_count, &stats.max_radii);
        }
        if let Some(r) = &mut self.resident {
            r.stale = false;
        }
        Ok(())
    }

    fn upload_if_dirty(&mut self) -> Result<(), GpuError> {
        if !self.resident.as_ref().is_some_and(|r| r.dirty) {
            return Ok(());
        }
        let moments: [(&[f32], &[f32]); GROUPS] =
            std::array::from_fn(|g| self.adam.moments(ParamGroup::ALL[g]));
        gpu_of(&mut self.rasterizer)?.upload_resident(
            &self.splats,
            moments,
            &self.splats.meta.frozen,
        )?;
        if let Some(r) = &mut self.resident {
            r.dirty = false;
            r.stale = false;
        }
        Ok(())
    }

    /// The checkpoint back in place of a model the GPU damaged (non-finite values on the
    /// device); uploaded again before the next step.
    fn restore_checkpoint(&mut self, step: u32, started: Instant, reason: String) -> StepReport {
        self.splats.clone_from(&self.checkpoint.splats);
        self.adam.clone_from(&self.checkpoint.adam);
        self.densifier.clone_from(&self.checkpoint.densifier);
        if let Some(r) = &mut self.resident {
            r.dirty = true;
            r.stale = false;
        }
        self.steps_done = step;
        self.timings.total += started.elapsed().as_secs_f64();
        StepReport {
            step,
            loss: f32::NAN,
            rolled_back: Some(format!(
                "{reason}; model restored to step {}",
                self.checkpoint_step
            )),
        }
    }

    /// One optimisation step with the model on the GPU.
    pub(super) fn step_resident(&mut self) -> StepReport {
        let step = self.steps_done + 1;
        let started = Instant::now();
        let view_index = self.next_view();
        let settings = self.step_settings(step);
        match self.resident_gpu_work(step, view_index, &settings, started) {
            Ok(Some(report)) => return report,
            Ok(None) => {}
            Err(e) => {
                self.note_gpu_fault(e);
                self.steps_done = step;
                return StepReport {
                    step,
                    loss: f32::NAN,
                    rolled_back: None,
                };
            }
        }
        let loss = self.last_loss;

        // Density control and checkpoints on the CPU, when due (they need the model there).
        let t = Instant::now();
        let densify_due = self.densifier.as_ref().is_some_and(|d| d.due(step));
        let prune = self.importance_prune_due(step);
        let checkpoint_due = step - self.checkpoint_step >= CHECKPOINT_EVERY;
        let mut changed = false;
        if densify_due || prune.is_some() || checkpoint_due || step >= self.spec.iterations {
            if let Err(e) = self.try_sync() {
                self.note_gpu_fault(e);
                self.steps_done = step;
                return StepReport {
                    step,
                    loss,
                    rolled_back: None,
                };
            }
            if let Some(densifier) = &mut self.densifier {
                let report =
                    densifier.after_step(step, &mut self.splats, &mut self.adam, self.extent);
                changed = report.densified || report.opacity_reset;
            }
            if let Some(keep) = prune {
                self.prune_by_importance(keep);
                changed = true;
            }
        }
        if changed && let Some(r) = &mut self.resident {
            r.dirty = true;
        }
        self.timings.densify += t.elapsed().as_secs_f64();

        self.steps_done = step;
        if (changed || checkpoint_due)
            && let Some(what) = self.scan_and_checkpoint()
        {
            return self.restore_checkpoint(step, started, format!("{what} became non-finite"));
        }
        self.timings.total += started.elapsed().as_secs_f64();
        StepReport {
            step,
            loss,
            rolled_back: None,
        }
    }

    /// Upload if needed, forward, loss, backward and Adam: Some(report) when the step is
    /// rolled back, the loss left in `last_loss` otherwise.
    fn resident_gpu_work(
        &mut self,
        step: u32,
        view_index: usize,
        settings: &RenderSettings,
        started: Instant,
    ) -> Result<Option<StepReport>, GpuError> {
        self.upload_if_dirty()?;
        if self.resident.as_ref().is_some_and(|r| r.loss_on_gpu) {
            return self.resident_step_with_gpu_loss(step, view_index, settings, started);
        }
        let t = Instant::now();
        let camera = self.views[view_index].camera;
        gpu_of(&mut self.rasterizer)?.forward_resident(&camera, settings, &mut self.out)?;
        self.timings.forward += t.elapsed().as_secs_f64();
        self.timings.rasterize += t.elapsed().as_secs_f64();

        let t = Instant::now();
        let (loss, labels_on) = self.render_loss(view_index, step);
        self.timings.loss += t.elapsed().as_secs_f64();
        if !loss.is_finite() {
            // Nothing on the GPU moved yet: skip the step.
            self.steps_done = step;
            self.timings.total += started.elapsed().as_secs_f64();
            return Ok(Some(StepReport {
                step,
                loss: f32::NAN,
                rolled_back: Some(format!("loss is {loss}; step skipped")),
            }));
        }

        let t = Instant::now();
        let groups = self.group_steps(step);
        let betas = (self.adam.beta1, self.adam.beta2, self.adam.eps);
        let v_out = PixelGrads {
            color: &self.v_color,
            alpha: None,
            depth: None,
            labels: labels_on.then_some(self.v_labels.as_slice()),
        };
        let bits = gpu_of(&mut self.rasterizer)?.step_resident(&v_out, &groups, betas)?;
        self.timings.backward += t.elapsed().as_secs_f64();
        self.timings.rasterize_backward += t.elapsed().as_secs_f64();
        if let Some(r) = &mut self.resident {
            r.stale = true;
        }
        if bits != 0 {
            let what = non_finite_reason(bits);
            return Ok(Some(self.restore_checkpoint(step, started, what)));
        }
        self.last_loss = loss;
        Ok(None)
    }

    /// The optimiser's step sizes for `step` (counting the step in the CPU optimiser).
    fn group_steps(&mut self, step: u32) -> [GroupStep; GROUPS] {
        let lrs = self.lrs.for_step(step, self.extent);
        let bias = self.adam.advance(&self.groups);
        std::array::from_fn(|g| match bias[g] {
            Some((bias1, bias2_sqrt)) => GroupStep {
                step_size: lrs[g] / bias1,
                inv_bias2_sqrt: 1.0 / bias2_sqrt,
                on: true,
            },
            None => GroupStep::default(),
        })
    }

    /// Forward, loss, backward and Adam all on the GPU: one submission, the non-finite bits and
    /// the loss's partial sums read back.
    fn resident_step_with_gpu_loss(
        &mut self,
        step: u32,
        view_index: usize,
        settings: &RenderSettings,
        started: Instant,
    ) -> Result<Option<StepReport>, GpuError> {
        let t = Instant::now();
        let groups = self.group_steps(step);
        let betas = (self.adam.beta1, self.adam.beta2, self.adam.eps);
        let view = &self.views[view_index];
        let channels = self.splats.label_channels;
        let targets = self.spec.targets;
        let label_weight = self.label_weight_at(step);
        let labels_on = targets.label_weight > 0.0
            && channels > 0
            && view.labels.len() == channels
            && channels <= MAX_LABEL_CHANNELS;
        let masks: [Option<&[u8]>; MAX_LABEL_CHANNELS] = std::array::from_fn(|k| {
            view.labels
                .get(k)
                .filter(|_| labels_on)
                .map(|m| m.data.as_slice())
        });
        let target = LossTarget {
            photo: &view.image.data,
            region: self.regions[view_index].as_deref(),
            labels: &masks[..channels.min(MAX_LABEL_CHANNELS)],
        };
        let weights = LossWeights {
            ssim_lambda: targets.ssim_lambda,
            rgb_weight: targets.rgb_weight.max(0.0),
            label_weight,
            pos_weight: self.label_params.pos_weight,
            eps: self.label_params.eps,
            window: gaussian_window(),
        };
        let camera = view.camera;
        let gpu = gpu_of(&mut self.rasterizer)?;
        let (loss, bits) =
            gpu.step_resident_with_loss(&camera, settings, &target, &weights, &groups, betas)?;
        // The forward is timed apart; the loss, backward and Adam are one submission.
        let forward = gpu.timings().raster_forward.as_secs_f64();
        let rest = (t.elapsed().as_secs_f64() - forward).max(0.0);
        self.timings.forward += forward;
        self.timings.rasterize += forward;
        self.timings.backward += rest;
        self.timings.rasterize_backward += rest;
        if let Some(r) = &mut self.resident {
            r.stale = true;
        }
        if bits != 0 || !loss.is_finite() {
            let what = if bits == 0 {
                format!("loss is {loss}")
            } else {
                non_finite_reason(bits)
            };
            return Ok(Some(self.restore_checkpoint(step, started, what)));
        }
        self.last_loss = loss;
        Ok(None)
    }
}
