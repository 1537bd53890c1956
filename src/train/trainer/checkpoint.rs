//! The trainer's rollback checkpoints: a copy of the model, Adam and the density statistics
//! every `CHECKPOINT_EVERY` steps and after every density change, taken only after a full scan
//! finds the model finite, and restored when a step damages it.

use std::time::Instant;

use super::{StepReport, Trainer};
use crate::raster::SplatGrads;
use crate::splats::Splats;
use crate::train::adam::Adam;
use crate::train::densify::Densifier;
use crate::train::guards::first_non_finite_param;

/// State restored by a rollback.
#[derive(Clone)]
pub(super) struct Checkpoint {
    pub(super) splats: Splats,
    pub(super) adam: Adam,
    pub(super) densifier: Option<Densifier>,
}

impl Trainer {
    /// A full scan of the model, then a checkpoint of it: NaN in Gaussians no step looked at
    /// (culled, or made by density control) never survives into a checkpoint. Returns what was
    /// not finite instead of checkpointing it.
    pub(super) fn scan_and_checkpoint(&mut self) -> Option<&'static str> {
        let t = Instant::now();
        let bad = first_non_finite_param(&self.splats);
        if bad.is_none() {
            self.take_checkpoint();
        }
        self.timings.checks += t.elapsed().as_secs_f64();
        bad
    }

    pub(super) fn take_checkpoint(&mut self) {
        self.checkpoint.splats.clone_from(&self.splats);
        self.checkpoint.adam.clone_from(&self.adam);
        self.checkpoint.densifier.clone_from(&self.densifier);
        self.checkpoint_step = self.steps_done;
    }

    /// Undoes a bad step: when the model itself is damaged, restores the last checkpoint; the
    /// step still counts, so a run always ends.
    pub(super) fn roll_back(&mut self, step: u32, started: Instant, reason: String) -> StepReport {
        let t = Instant::now();
        let mut reason = reason;
        if first_non_finite_param(&self.splats).is_some() || self.adam.len() != self.splats.len() {
            self.splats.clone_from(&self.checkpoint.splats);
            self.adam.clone_from(&self.checkpoint.adam);
            self.densifier.clone_from(&self.checkpoint.densifier);
            self.grads = SplatGrads::zeros(&self.splats);
            self.refresh_trainable();
            reason.push_str(&format!(
                "; model restored to step {}",
                self.checkpoint_step
            ));
        } else {
            reason.push_str("; step skipped");
        }
        self.steps_done = step;
        self.timings.checks += t.elapsed().as_secs_f64();
        self.timings.total += started.elapsed().as_secs_f64();
        StepReport {
            step,
            loss: f32::NAN,
            rolled_back: Some(reason),
        }
    }
}
