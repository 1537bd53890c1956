//! The trainer's side of the rasterizer's frozen caches (`raster::FrameFocus`): in a run that
//! trains only some Gaussians (a refinement, a survey update), which ones, and a generation
//! that changes whenever a frozen Gaussian's parameters may have changed, so that no view's
//! cached projection of them outlives them.

use super::Trainer;
use crate::raster::FrameFocus;

/// Which Gaussians the focused frames train and under which generation.
#[derive(Debug, Default)]
pub(super) struct FrozenCache {
    /// Ascending indices of the trainable Gaussians; None: every frame is rendered whole (no
    /// trainable mask, density control on, or switched off).
    trainable: Option<Vec<u32>>,
    generation: u64,
    /// Off: every frame whole (`Trainer::set_frozen_cache`).
    disabled: bool,
}

impl FrozenCache {
    /// Any cached projection may be stale from now on.
    pub fn invalidate(&mut self) {
        self.generation += 1;
    }

    /// The focus of a step on view `view`, for the renderer.
    pub fn focus(&self, view: usize) -> Option<FrameFocus<'_>> {
        self.trainable.as_deref().map(|trainable| FrameFocus {
            trainable,
            view,
            generation: self.generation,
        })
    }
}

impl Trainer {
    /// Reuses each view's projection and depth order of the frozen Gaussians between steps
    /// (on by default in runs with a trainable mask and no density control). Off renders
    /// every step whole: the same images and gradients, for comparison and benchmarks.
    pub fn set_frozen_cache(&mut self, on: bool) {
        self.frozen_cache.disabled = !on;
        self.refresh_trainable();
    }

    /// The trainable set again from the model's frozen flags (after a density change, at the
    /// start), and a new generation.
    pub(super) fn refresh_trainable(&mut self) {
        let cache = &mut self.frozen_cache;
        cache.invalidate();
        let focused = !cache.disabled
            && self.spec.trainable.is_some()
            && self.densifier.is_none()
            && self.resident.is_none();
        cache.trainable = focused.then(|| {
            (0..self.splats.len() as u32)
                .filter(|&g| !self.splats.meta.frozen[g as usize])
                .collect()
        });
    }
}
