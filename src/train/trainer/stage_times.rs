//! Wall time per training stage, summed over steps: what `bench`, `train` and `refine` report.

use serde::Serialize;

/// Seconds spent per stage, summed over steps.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StageTimes {
    /// Raster forward as a whole, and its parts when the rasterizer reports them.
    pub forward: f64,
    pub project: f64,
    pub sort: f64,
    pub rasterize: f64,
    pub loss: f64,
    /// Raster backward as a whole, and its two parts.
    pub backward: f64,
    pub rasterize_backward: f64,
    pub project_backward: f64,
    /// NaN/Inf checks and checkpoints.
    pub checks: f64,
    pub optimizer: f64,
    pub densify: f64,
    pub total: f64,
}

impl StageTimes {
    /// Removes `earlier`, a copy of these times taken before, leaving the steps since.
    pub fn subtract(&mut self, earlier: &StageTimes) {
        self.forward -= earlier.forward;
        self.project -= earlier.project;
        self.sort -= earlier.sort;
        self.rasterize -= earlier.rasterize;
        self.loss -= earlier.loss;
        self.backward -= earlier.backward;
        self.rasterize_backward -= earlier.rasterize_backward;
        self.project_backward -= earlier.project_backward;
        self.checks -= earlier.checks;
        self.optimizer -= earlier.optimizer;
        self.densify -= earlier.densify;
        self.total -= earlier.total;
    }

    /// Milliseconds per step of every stage.
    pub fn per_step_ms(&self, steps: u32) -> StageTimes {
        let k = 1000.0 / steps.max(1) as f64;
        StageTimes {
            forward: self.forward * k,
            project: self.project * k,
            sort: self.sort * k,
            rasterize: self.rasterize * k,
            loss: self.loss * k,
            backward: self.backward * k,
            rasterize_backward: self.rasterize_backward * k,
            project_backward: self.project_backward * k,
            checks: self.checks * k,
            optimizer: self.optimizer * k,
            densify: self.densify * k,
            total: self.total * k,
        }
    }
}
