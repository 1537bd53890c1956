//! Training history for the live charts, the statistics panel and the exported charts: loss,
//! PSNR and Gaussian count against wall time, bounded in memory by thinning old samples. Data
//! only; it is filled from job progress here, in one place, for the viewer and the CLI alike.

use serde::{Deserialize, Deserializer, Serialize};

use crate::train::job::Progress;

/// One progress report of a training run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Seconds since the run started.
    pub wall_s: f64,
    pub step: u32,
    /// NaN in the phases that do not train (JSON: null).
    #[serde(deserialize_with = "nan_when_null")]
    pub loss: f64,
    /// Training-batch PSNR, dB (NaN when not reported; JSON: null).
    #[serde(deserialize_with = "nan_when_null")]
    pub psnr: f64,
    pub gaussians: usize,
}

/// A held-out evaluation during or after training.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalSample {
    pub wall_s: f64,
    pub step: u32,
    #[serde(deserialize_with = "nan_when_null")]
    pub psnr: f64,
}

/// serde_json writes NaN as null; read it back as NaN.
fn nan_when_null<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(deserializer)?.unwrap_or(f64::NAN))
}

/// Bounded history: when full, every other sample of the older half is dropped, so the curve
/// keeps its shape over long runs.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct History {
    pub samples: Vec<Sample>,
    pub evals: Vec<EvalSample>,
}

impl History {
    pub const CAPACITY: usize = 4096;

    pub fn clear(&mut self) {
        self.samples.clear();
        self.evals.clear();
    }

    pub fn push(&mut self, sample: Sample) {
        if self.samples.len() >= Self::CAPACITY {
            let half = self.samples.len() / 2;
            let mut i = 0;
            self.samples.retain(|_| {
                i += 1;
                // Keep every other sample of the older half, all of the newer half.
                i > half || i % 2 == 1
            });
        }
        self.samples.push(sample);
    }

    pub fn push_eval(&mut self, eval: EvalSample) {
        self.evals.push(eval);
    }

    /// Records one progress report seen at `wall_s` (seconds since the run started): a sample,
    /// and a held-out evaluation when the step had one.
    pub fn record_progress(&mut self, progress: &Progress, wall_s: f64) {
        self.push(Sample {
            wall_s,
            step: progress.step,
            loss: f64::from(progress.loss),
            psnr: f64::NAN,
            gaussians: progress.gaussians,
        });
        if let Some(psnr) = progress.psnr {
            self.push_eval(EvalSample {
                wall_s,
                step: progress.step,
                psnr,
            });
        }
    }

    /// Records the finished model's held-out PSNR at the last recorded step.
    pub fn record_final(&mut self, heldout_psnr: Option<f64>, wall_s: f64) {
        if let (Some(psnr), Some(last)) = (heldout_psnr, self.samples.last()) {
            let step = last.step;
            self.push_eval(EvalSample { wall_s, step, psnr });
        }
    }

    pub fn last(&self) -> Option<&Sample> {
        self.samples.last()
    }

    /// Iterations per second over the last few seconds of samples.
    pub fn iterations_per_second(&self) -> Option<f64> {
        let last = self.samples.last()?;
        let window_start = last.wall_s - 3.0;
        let first = self
            .samples
            .iter()
            .find(|s| s.wall_s >= window_start)
            .filter(|s| s.step < last.step)?;
        let dt = last.wall_s - first.wall_s;
        if !(dt > 0.0) {
            return None;
        }
        Some(f64::from(last.step - first.step) / dt)
    }

    /// `(wall_s, value)` series for plotting, skipping non-finite values.
    pub fn series(&self, value: impl Fn(&Sample) -> f64) -> Vec<[f64; 2]> {
        self.samples
            .iter()
            .map(|s| [s.wall_s, value(s)])
            .filter(|p| p[1].is_finite())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_history_survives_json_with_its_gaps() {
        let mut history = History::default();
        for (step, loss) in [(0, f64::NAN), (1, 0.5), (2, 0.25)] {
            history.push(Sample {
                wall_s: f64::from(step) * 0.1,
                step,
                loss,
                psnr: f64::NAN,
                gaussians: 10 + step as usize,
            });
        }
        history.push_eval(EvalSample {
            wall_s: 0.2,
            step: 2,
            psnr: 21.5,
        });
        let text = serde_json::to_string(&history).expect("serialise");
        let back: History = serde_json::from_str(&text).expect("read back");
        assert_eq!(back.series(|s| s.loss), vec![[0.1, 0.5], [0.2, 0.25]]);
        assert!(back.samples.iter().all(|s| s.psnr.is_nan()));
        assert_eq!(back.evals, history.evals);
        assert_eq!(back.samples.len(), 3);
    }
}
