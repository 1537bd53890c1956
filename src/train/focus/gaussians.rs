//! Which Gaussians a focused run trains and how: the spec of a run on a trained model with only
//! those Gaussians free, fine-tuned as they are or densified; and, in its result, the Gaussians
//! it trained or created, found again by id (densification reorders and adds Gaussians).

use std::collections::HashSet;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::splats::Splats;
use crate::train::spec::{DensifyPolicy, TrainSpec, densify_for_iterations};

/// Fine-tune the trained Gaussians as they are, or let them densify (clone, split, prune) as they
/// train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Strategy {
    /// Position, colour, opacity, scale, rotation and labels of the selection; count unchanged.
    Finetune,
    /// The same plus density control restricted to the selection; new Gaussians are trainable
    /// and inherit their parent's damage labels and state.
    Retrain,
}

impl std::str::FromStr for Strategy {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "finetune" => Ok(Strategy::Finetune),
            "retrain" => Ok(Strategy::Retrain),
            _ => Err(format!(
                "unknown strategy {text:?}: use finetune or retrain"
            )),
        }
    }
}

/// The spec of a focused run of `iterations` steps (at least one) on the trained `model`, in
/// which only the Gaussians `trainable` (indices into `model`) change.
pub fn focused_spec(
    model: &Splats,
    trainable: &[u32],
    strategy: Strategy,
    iterations: u32,
    seed: u64,
    background: Vec3,
) -> TrainSpec {
    let iterations = iterations.max(1);
    let mut spec = TrainSpec::reconstruction(iterations);
    spec.sh_degree = model.sh_degree;
    spec.seed = seed;
    spec.background = background;
    spec.eval_every = 0;
    spec.densify = match strategy {
        Strategy::Finetune => DensifyPolicy::Off,
        Strategy::Retrain => DensifyPolicy::Adaptive(densify_for_iterations(iterations, seed)),
    };
    continue_trained(&mut spec);
    let mut free = vec![false; model.len()];
    for &g in trainable {
        free[g as usize] = true;
    }
    spec.trainable = Some(free);
    spec
}

/// Sets `spec` to continue a trained start rather than begin from points: every SH band from the
/// first step, and no opacity reset. A reset blanks the start: in a short local run (a
/// refinement, an update) the trained Gaussians mid-way, while the frozen rest of the model
/// keeps floaters out anyway; in a block started from the context, 100–150 steps of recovery
/// out of its share (on the small bridge at 1,200 steps, the merged twin's held-out PSNR was
/// 24.84 dB with resets from the initial points, 25.19 without them, and 25.47 from the
/// context; the whole run: 25.89; docs/CLUSTER.md).
pub fn continue_trained(spec: &mut TrainSpec) {
    spec.sh_ramp_every = 0;
    if let DensifyPolicy::Adaptive(densify) = &mut spec.densify {
        densify.opacity_reset_every = 0;
    }
}

/// Per Gaussian of a focused run's `result`, whether the run trained it (its id is that of one of
/// `input`'s Gaussians `trained`) or created it (an id from `first_new_id` on).
pub fn trained_or_created(
    result: &Splats,
    input: &Splats,
    trained: &[u32],
    first_new_id: u64,
) -> Vec<bool> {
    let trained: HashSet<u64> = trained
        .iter()
        .map(|&g| input.meta.ids[g as usize])
        .collect();
    result
        .meta
        .ids
        .iter()
        .map(|id| *id >= first_new_id || trained.contains(id))
        .collect()
}
