//! The training loop over a `TrainSpec`: seeded view order, forward raster, loss and its
//! backward, raster backward, Adam, density control; NaN/Inf steps are rolled back. Deterministic
//! for a seed and thread count; allocation-free per step once buffers have grown. No I/O here.

use std::collections::HashMap;
use std::time::Instant;

use glam::Vec3;

use crate::raster::{
    PixelGrads, RasterBackend, Rasterizer, RenderOutput, RenderSettings, SplatGrads,
};
use crate::splats::Splats;
use crate::train::adam::{Adam, GroupFlags, LearningRates, ParamGrads, ParamGroup};
use crate::train::appearance::AppearanceModel;
use crate::train::densify::{Densifier, camera_extent};
use crate::train::evaluate::{EvalScores, evaluate_with};
use crate::train::guards::first_non_finite_param;
use crate::train::importance::{importance, prune_to};
use crate::train::label_loss::LabelLossParams;
use crate::train::loss::LossWorkspace;
use crate::train::scale_cap::ScaleCap;
use crate::train::schedule::sh_degree_for_step;
use crate::train::spec::{TrainSpec, TrainView};

/// Steps between rollback checkpoints (also taken after every density change). A rollback loses
/// at most this many steps; a copy every 100 steps costs well under 1 % of training time.
const CHECKPOINT_EVERY: u32 = 100;

#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("no training views")]
    NoViews,
    #[error("view index {index} in the spec is out of range ({count} views)")]
    ViewIndex { index: usize, count: usize },
    #[error("view {name}: image is {got} values, expected {expected} for its camera")]
    ImageSize {
        name: String,
        got: usize,
        expected: usize,
    },
    #[error("view {name}: {what} mask is {got} pixels, expected {expected}")]
    MaskSize {
        name: String,
        what: String,
        got: usize,
        expected: usize,
    },
    #[error("the trainable mask has {got} entries for {expected} Gaussians")]
    TrainableMask { got: usize, expected: usize },
    #[error("per-Gaussian rates: {0}")]
    Rates(String),
    #[error("the initial splats are inconsistent: {0}")]
    Splats(String),
    #[error("the initial splats contain NaN or Inf ({0})")]
    NonFinite(&'static str),
    #[error("backend {backend}: {source}")]
    Backend {
        backend: crate::train::backend_choice::Backend,
        source: crate::gpu::GpuError,
    },
    #[error("the renderer failed during training: {0}")]
    RendererFault(String),
}

/// What one step did.
#[derive(Clone, Debug, PartialEq)]
pub struct StepReport {
    /// 1-based index of the step.
    pub step: u32,
    /// Its loss (NaN when rolled back).
    pub loss: f32,
    /// Set when the step produced NaN/Inf and was undone.
    pub rolled_back: Option<String>,
}

/// Steps between pinning the photos' mean light to the identity (`AppearanceModel::recentre`):
/// the drift it removes is slow, and each pin rescales every SH coefficient.
const APPEARANCE_RECENTRE_EVERY: u32 = 100;

mod checkpoint;
mod frozen_cache;
mod stage_times;
pub use stage_times::StageTimes;
mod resident;
mod step_loss;
mod trainer_inputs;
use checkpoint::Checkpoint;
use trainer_inputs::{check_view, region_tiles};

/// One training run in progress.
pub struct Trainer {
    spec: TrainSpec,
    splats: Splats,
    views: Vec<TrainView>,
    /// Loss region per view as weights (0/1), converted once.
    regions: Vec<Option<Vec<f32>>>,
    /// Per view with a loss region, the tiles that region needs rendered (see `region_tiles`).
    tiles: Vec<Option<Vec<bool>>>,
    /// Per view with a loss region, its pixels packed for `Rasterizer::set_active_pixels`: the
    /// only ones rendered inside those tiles.
    pixels: Vec<Option<Vec<u16>>>,
    /// The renderer (the CPU rasterizer unless `with_backend` chose another).
    rasterizer: Box<dyn RasterBackend>,
    out: RenderOutput,
    grads: SplatGrads,
    adam: Adam,
    densifier: Option<Densifier>,
    scale_cap: Option<ScaleCap>,
    /// Per training view, its light (when the spec asks for it) and the render through it.
    appearance: Option<AppearanceModel>,
    lit_color: Vec<f32>,
    lrs: LearningRates,
    groups: GroupFlags,
    extent: f32,
    loss_ws: LossWorkspace,
    label_params: LabelLossParams,
    v_color: Vec<f32>,
    v_labels: Vec<f32>,
    rng: fastrand::Rng,
    /// Shuffled view order of the current epoch and the position in it.
    order: Vec<usize>,
    order_pos: usize,
    steps_done: u32,
    timings: StageTimes,
    checkpoint: Checkpoint,
    checkpoint_step: u32,
    /// Frozen flags of the input model by Gaussian id, restored when the run ends (the run's own
    /// trainable mask travels in `meta.frozen` through densification).
    input_frozen: Option<HashMap<u64, bool>>,
    /// Set when the model lives on the GPU between syncs (`resident.rs`).
    resident: Option<resident::Resident>,
    /// The loss of the last GPU-resident step.
    last_loss: f32,
    /// Which Gaussians the renderer may treat as frozen between steps (`frozen_cache.rs`).
    frozen_cache: frozen_cache::FrozenCache,
}

impl Trainer {
    /// Prepares a run on the CPU rasterizer: selects the spec's views, applies the trainable
    /// mask, sizes every buffer.
    pub fn new(
        spec: TrainSpec,
        splats: Splats,
        views: Vec<TrainView>,
    ) -> Result<Trainer, TrainError> {
        Trainer::with_backend(spec, splats, views, Box::new(Rasterizer::new()))
    }

    /// `new` on another renderer (a GPU backend).
    pub fn with_backend(
        spec: TrainSpec,
        mut splats: Splats,
        views: Vec<TrainView>,
        mut backend: Box<dyn RasterBackend>,
    ) -> Result<Trainer, TrainError> {
        splats.check_lengths().map_err(TrainError::Splats)?;
        if let Some(what) = first_non_finite_param(&splats) {
            return Err(TrainError::NonFinite(what));
        }
        let views = match &spec.views {
            None => views,
            Some(indices) => {
                let count = views.len();
                if let Some(&index) = indices.iter().find(|&&i| i >= count) {
                    return Err(TrainError::ViewIndex { index, count });
                }
                indices.iter().map(|&i| views[i].clone()).collect()
            }
        };
        if views.is_empty() {
            return Err(TrainError::NoViews);
        }
        for view in &views {
            check_view(view, splats.label_channels)?;
        }
        let input_frozen = match &spec.trainable {
            None => None,
            Some(mask) => {
                if mask.len() != splats.len() {
                    return Err(TrainError::TrainableMask {
                        got: mask.len(),
                        expected: splats.len(),
                    });
                }
                let saved = splats
                    .meta
                    .ids
                    .iter()
                    .copied()
                    .zip(splats.meta.frozen.iter().copied())
                    .collect();
                for (frozen, &trainable) in splats.meta.frozen.iter_mut().zip(mask) {
                    *frozen = !trainable;
                }
                Some(saved)
            }
        };
        if splats.sh_degree < spec.sh_degree {
            splats.set_sh_degree(spec.sh_degree);
        }

        let centres: Vec<Vec3> = views.iter().map(|v| v.camera.position()).collect();
        let extent = camera_extent(&centres).max(1e-6);
        let mut lrs = LearningRates {
            position_max_steps: spec.iterations,
            ..LearningRates::default()
        };
        spec.lr.apply(&mut lrs);
        let groups = spec.groups.flags();
        let densifier = spec
            .densify_config()
            .map(|config| Densifier::new(config, splats.len()));
        let resident = resident::can_be_resident(&spec, &mut backend).then(resident::Resident::new);
        // Moments for the trainable Gaussians only: a focused run's frozen rest (a block's
        // context, the untouched twin of a refinement) would keep zeros there. The GPU-resident
        // step's Adam holds them for every Gaussian.
        let mut adam = match resident {
            Some(_) => Adam::new(&splats),
            None => Adam::for_trainable(&splats),
        };
        if let Some(rates) = &spec.geometry_rate {
            for group in [
                ParamGroup::Means,
                ParamGroup::LogScales,
                ParamGroup::Rotations,
                ParamGroup::RawOpacities,
            ] {
                adam.set_rates(group, Some(rates.clone()))
                    .map_err(TrainError::Rates)?;
            }
        }
        let scale_cap = spec
            .max_scale_growth
            .map(|growth| ScaleCap::new(&splats, |g| !splats.meta.frozen[g], growth));
        let regions = views
            .iter()
            .map(|v| {
                v.region.as_ref().map(|m| {
                    m.data
                        .iter()
                        .map(|&b| if b != 0 { 1.0 } else { 0.0 })
                        .collect()
                })
            })
            .collect();
        let tiles = views
            .iter()
            .map(|v| v.region.as_ref().map(region_tiles))
            .collect();
        let pixels = views
            .iter()
            .map(|v| {
                v.region
                    .as_ref()
                    .map(|m| crate::raster::pixel_rows(&m.data, m.width, m.height))
            })
            .collect();
        let grads = SplatGrads::zeros(&splats);
        let checkpoint = Checkpoint {
            splats: splats.clone(),
            adam: adam.clone(),
            densifier: densifier.clone(),
        };
        let rng = fastrand::Rng::with_seed(spec.seed);
        let mut trainer = Trainer {
            frozen_cache: frozen_cache::FrozenCache::default(),
            resident,
            last_loss: f32::NAN,
            regions,
            tiles,
            pixels,
            rasterizer: backend,
            out: RenderOutput::default(),
            grads,
            adam,
            densifier,
            scale_cap,
            appearance: spec
                .appearance
                .map(|config| AppearanceModel::new(views.len(), config)),
            lit_color: Vec::new(),
            lrs,
            groups,
            extent,
            loss_ws: LossWorkspace::new(),
            label_params: LabelLossParams {
                pos_weight: spec.targets.label_pos_weight,
                ..LabelLossParams::default()
            },
            v_color: Vec::new(),
            v_labels: Vec::new(),
            rng,
            order: Vec::with_capacity(views.len()),
            order_pos: 0,
            steps_done: 0,
            timings: StageTimes::default(),
            checkpoint,
            checkpoint_step: 0,
            input_frozen,
            spec,
            splats,
            views,
        };
        trainer.refresh_trainable();
        Ok(trainer)
    }

    /// Why the renderer stopped working, if it did (see `RasterBackend::fault`).
    pub fn renderer_fault(&self) -> Option<&str> {
        self.resident
            .as_ref()
            .and_then(|r| r.fault())
            .or(self.rasterizer.fault())
    }

    pub fn total_steps(&self) -> u32 {
        self.spec.iterations
    }

    pub fn steps_done(&self) -> u32 {
        self.steps_done
    }

    pub fn is_done(&self) -> bool {
        self.steps_done >= self.spec.iterations
    }

    pub fn view_count(&self) -> usize {
        self.views.len()
    }

    pub fn spec(&self) -> &TrainSpec {
        &self.spec
    }

    /// The model; in a GPU-resident run, as of the last `sync` (its count is always current).
    pub fn splats(&self) -> &Splats {
        &self.splats
    }

    /// Accumulated stage times.
    pub fn timings(&self) -> &StageTimes {
        &self.timings
    }

    /// The scene extent the position rate and density control are scaled by.
    pub fn extent(&self) -> f32 {
        self.extent
    }

    /// SH degree rendered at the current step.
    pub fn active_sh_degree(&self) -> u32 {
        self.sh_degree_at(self.steps_done.max(1))
    }

    fn sh_degree_at(&self, step: u32) -> u32 {
        sh_degree_for_step(
            step,
            self.spec.sh_degree.min(self.splats.sh_degree),
            self.spec.sh_ramp_every,
        )
    }

    /// How step `step` renders: the run's background, the SH degree its ramp has reached.
    fn step_settings(&self, step: u32) -> RenderSettings {
        RenderSettings::new(self.spec.background, self.sh_degree_at(step))
    }

    /// Each training view's learnt light (empty when the spec learns none).
    pub fn appearance(&self) -> Vec<crate::scene::project::ColourTransform> {
        self.appearance
            .as_ref()
            .map(|a| a.transforms())
            .unwrap_or_default()
    }

    /// The trained model, with the input's frozen flags restored.
    pub fn into_splats(mut self) -> Splats {
        self.sync();
        if let Some(saved) = &self.input_frozen {
            for (frozen, id) in self
                .splats
                .meta
                .frozen
                .iter_mut()
                .zip(&self.splats.meta.ids)
            {
                *frozen = saved.get(id).copied().unwrap_or(false);
            }
        }
        self.splats
    }

    fn next_view(&mut self) -> usize {
        if self.order_pos >= self.order.len() {
            self.order.clear();
            self.order.extend(0..self.views.len());
            self.rng.shuffle(&mut self.order);
            self.order_pos = 0;
        }
        let v = self.order[self.order_pos];
        self.order_pos += 1;
        v
    }

    /// One optimisation step on the next view.
    pub fn step(&mut self) -> StepReport {
        self.detach_labels_if_due(self.steps_done + 1);
        if self.resident.is_some() {
            return self.step_resident();
        }
        let step = self.steps_done + 1;
        let started = Instant::now();
        let view_index = self.next_view();
        let settings = self.step_settings(step);

        // Forward, of the tiles the view's loss region needs.
        let t = Instant::now();
        self.rasterizer
            .set_active_tiles(self.tiles[view_index].as_deref());
        self.rasterizer
            .set_active_pixels(self.pixels[view_index].as_deref());
        self.rasterizer
            .set_focus(self.frozen_cache.focus(view_index));
        self.rasterizer.forward(
            &self.splats,
            &self.views[view_index].camera,
            &settings,
            &mut self.out,
        );
        self.timings.forward += t.elapsed().as_secs_f64();
        let parts = self.rasterizer.timings();
        self.timings.project += parts.project.as_secs_f64();
        self.timings.sort += parts.sort.as_secs_f64();
        self.timings.rasterize += parts.raster_forward.as_secs_f64();

        // Loss and its gradient w.r.t. the render.
        let t = Instant::now();
        let (loss, labels_on) = self.render_loss(view_index, step);
        self.timings.loss += t.elapsed().as_secs_f64();
        if !loss.is_finite() {
            return self.roll_back(step, started, format!("loss is {loss}"));
        }

        // Backward.
        let t = Instant::now();
        let v_out = PixelGrads {
            color: &self.v_color,
            alpha: None,
            depth: None,
            labels: labels_on.then_some(self.v_labels.as_slice()),
        };
        self.rasterizer.backward(
            &self.splats,
            &self.views[view_index].camera,
            &settings,
            &v_out,
            &mut self.grads,
        );
        self.timings.backward += t.elapsed().as_secs_f64();
        let parts = self.rasterizer.timings();
        self.timings.rasterize_backward += parts.raster_backward.as_secs_f64();
        self.timings.project_backward += parts.project_backward.as_secs_f64();

        // Optimiser. It also checks every gradient it reads and every value it writes, so a
        // NaN/Inf from the backward or from the update itself rolls the step back.
        let t = Instant::now();
        let lrs = self.lrs.for_step(step, self.extent);
        let grads = ParamGrads {
            v_means: &self.grads.v_means,
            v_log_scales: &self.grads.v_log_scales,
            v_rotations: &self.grads.v_rotations,
            v_raw_opacities: &self.grads.v_raw_opacities,
            v_sh: &self.grads.v_sh,
            v_raw_labels: &self.grads.v_raw_labels,
        };
        let non_finite = self.adam.step(
            &mut self.splats,
            &grads,
            &lrs,
            &self.groups,
            Some(&self.grads.visible),
        );
        if let Some(cap) = &self.scale_cap {
            cap.apply(&mut self.splats);
        }
        self.timings.optimizer += t.elapsed().as_secs_f64();
        if let Some(what) = non_finite {
            return self.roll_back(step, started, what.to_string());
        }

        // Density control.
        let t = Instant::now();
        let mut changed = false;
        if let Some(densifier) = &mut self.densifier {
            if step < densifier.config.stop {
                densifier.accumulate(&self.grads.v_means2d_norm, self.rasterizer.radii());
            }
            let report = densifier.after_step(step, &mut self.splats, &mut self.adam, self.extent);
            changed = report.densified || report.opacity_reset;
        }
        if let Some(keep) = self.importance_prune_due(step) {
            self.prune_by_importance(keep);
            changed = true;
        }
        if let Some(appearance) = &mut self.appearance
            && appearance.active_at(step)
            && step.is_multiple_of(APPEARANCE_RECENTRE_EVERY)
        {
            let (gain, offset) = appearance.recentre();
            crate::train::appearance::fold_into_colours(&mut self.splats, gain, offset);
            // The next checkpoint holds the folded colours, which go with the recentred light.
            changed = true;
        }
        self.timings.densify += t.elapsed().as_secs_f64();
        if changed {
            // Frozen Gaussians may have moved, been added or removed, or changed colour.
            self.refresh_trainable();
        }

        self.steps_done = step;
        if (changed || step - self.checkpoint_step >= CHECKPOINT_EVERY)
            && let Some(what) = self.scan_and_checkpoint()
        {
            return self.roll_back(step, started, format!("{what} became non-finite"));
        }
        self.timings.total += started.elapsed().as_secs_f64();
        StepReport {
            step,
            loss,
            rolled_back: None,
        }
    }

    /// The budget to prune to at `step`: `DensifyConfig::prune_at` (by default the end of the
    /// densification window; the run's last step when the run ends first) of a spec with
    /// `DensifyConfig::prune_to`, if the model exceeds it.
    fn importance_prune_due(&self, step: u32) -> Option<usize> {
        let config = &self.densifier.as_ref()?.config;
        let keep = config.prune_to?;
        let at = config.prune_at.unwrap_or(config.stop);
        (step == at.min(self.spec.iterations) && self.splats.len() > keep).then_some(keep)
    }

    /// Prunes to the `keep` Gaussians with the most blending weight over the training views,
    /// keeping Adam and the density statistics in step.
    fn prune_by_importance(&mut self, keep: usize) {
        let settings = self.step_settings(self.steps_done.max(1));
        let score = importance(&self.splats, &self.views, &settings);
        let mask = prune_to(&mut self.splats, &score, keep);
        self.adam.retain(&mask);
        if let Some(densifier) = &mut self.densifier {
            densifier.reset_stats(self.splats.len());
        }
    }

    /// Mean PSNR and SSIM of the current model over `views`, at the current SH degree.
    pub fn evaluate(&mut self, views: &[TrainView]) -> EvalScores {
        self.sync();
        self.rasterizer.set_active_tiles(None);
        self.rasterizer.set_active_pixels(None);
        self.rasterizer.set_focus(None);
        let settings = self.step_settings(self.steps_done.max(1));
        evaluate_with(
            self.rasterizer.as_mut(),
            &mut self.out,
            &self.splats,
            views,
            &settings,
        )
    }

    /// Keeps Adam's moments for every Gaussian, frozen ones included, as runs did before
    /// `Adam::for_trainable`: the same model, for comparisons.
    #[doc(hidden)]
    pub fn keep_moments_for_every_gaussian(&mut self) {
        self.adam = self.adam.with_every_gaussian();
        self.checkpoint.adam = self.checkpoint.adam.with_every_gaussian();
    }

    /// Test hook: corrupts one Gaussian's base colour. Projection culls it from then on, and the
    /// full parameter scan before the next checkpoint must roll back.
    #[doc(hidden)]
    pub fn poison_for_test(&mut self, gaussian: usize) {
        let k3 = self.splats.sh_coeffs() * 3;
        self.splats.sh[gaussian * k3] = f32::NAN;
        self.frozen_cache.invalidate();
    }
}
