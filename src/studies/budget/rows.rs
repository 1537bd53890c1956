//! The budget study's rows and its file: one row per measured model, and per scene how it was
//! measured. The leaf the run and the chart look down to.

use serde::{Deserialize, Serialize};

/// One measured model of the study.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BudgetRow {
    pub scene: String,
    /// `full`, `budget 50%` (of the full run's count), `compact 50%` (of the full model).
    pub method: String,
    /// Mean held-out PSNR, dB.
    pub psnr: f64,
    pub gaussians: usize,
    /// Size of the model as PLY.
    pub bytes: u64,
    /// Wall time to make the model (a compact row includes the full run it starts from).
    pub seconds: f64,
}

/// How one scene was measured.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SceneRun {
    pub scene: String,
    pub dataset: String,
    pub width: u32,
    pub height: u32,
    pub iterations: u32,
    pub compact_iterations: u32,
    pub threads: usize,
}

/// `budget-study.json`: the rows of every scene measured into it so far.
#[derive(Debug, Default, Serialize, Deserialize)]
pub struct BudgetFile {
    #[serde(default)]
    pub scenes: Vec<SceneRun>,
    #[serde(default)]
    pub rows: Vec<BudgetRow>,
}

impl BudgetFile {
    /// Replaces `scene`'s rows and run with these, keeping the other scenes'.
    pub fn merge(&mut self, scene: SceneRun, rows: Vec<BudgetRow>) {
        self.rows.retain(|r| r.scene != scene.scene);
        self.rows.extend(rows);
        self.scenes.retain(|s| s.scene != scene.scene);
        self.scenes.push(scene);
    }
}
