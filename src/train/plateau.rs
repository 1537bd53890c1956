//! The stopping rule of a short local run (a refinement, a survey update): stop when the loss
//! stops improving. A step's loss is one view's, so single steps are noisy; the rule compares the
//! mean loss of whole windows of steps, and a window that does not beat the best mean before it
//! by a relative margin counts as flat. After `patience` flat windows in a row the run stops.

use serde::{Deserialize, Serialize};

/// When a run counts as no longer improving.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plateau {
    /// Steps per window (a multiple of the view count averages each view equally).
    pub window: u32,
    /// A window improves when its mean loss is below the best earlier window's by more than this
    /// fraction of it.
    pub min_gain: f32,
    /// Flat windows in a row that stop the run.
    pub patience: u32,
}

/// Watches a run's losses against a `Plateau`.
#[derive(Clone, Debug)]
pub struct PlateauWatch {
    rule: Plateau,
    sum: f64,
    count: u32,
    best: Option<f64>,
    flat: u32,
}

impl PlateauWatch {
    pub fn new(rule: Plateau) -> PlateauWatch {
        PlateauWatch {
            rule,
            sum: 0.0,
            count: 0,
            best: None,
            flat: 0,
        }
    }

    /// Adds one step's loss; true when the run should stop now. A non-finite loss (a step the
    /// guards rolled back) is not counted.
    pub fn push(&mut self, loss: f32) -> bool {
        if !loss.is_finite() {
            return false;
        }
        self.sum += f64::from(loss);
        self.count += 1;
        if self.count < self.rule.window.max(1) {
            return false;
        }
        let mean = self.sum / f64::from(self.count);
        (self.sum, self.count) = (0.0, 0);
        match self.best {
            Some(best) if mean >= best * (1.0 - f64::from(self.rule.min_gain)) => {
                self.flat += 1;
                self.best = Some(best.min(mean));
            }
            _ => {
                self.flat = 0;
                self.best = Some(mean);
            }
        }
        self.flat >= self.rule.patience.max(1)
    }
}

/// The step at which `rule` stops a run whose step losses were `losses` (None: it runs to the
/// end): what a rule would have done to a recorded run.
pub fn stop_step(rule: Plateau, losses: impl IntoIterator<Item = f32>) -> Option<u32> {
    let mut watch = PlateauWatch::new(rule);
    let mut step = 0u32;
    for loss in losses {
        step += 1;
        if watch.push(loss) {
            return Some(step);
        }
    }
    None
}
