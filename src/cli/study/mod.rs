//! `damage-twin study …`: measurements that answer an inspector's questions with numbers, each
//! writing JSON, CSV, a Markdown table and a chart. One file per study.

mod budget;
mod hierarchy;
mod mask_noise;
mod real;
mod segment;
mod stability;
mod update;

#[derive(clap::Subcommand, Debug)]
pub enum Study {
    /// How much mask error the twin removes: train on corrupted masks at each rate, compare the
    /// rendered masks with the clean ones.
    MaskNoise(mask_noise::MaskNoiseArgs),
    /// The hierarchy's efficiency: full high-resolution training against a coarse twin, coarse +
    /// fine-tune and coarse + retrain, in wall time and held-out accuracy.
    Hierarchy(hierarchy::HierarchyArgs),
    /// The Gaussian budget: a full run against `train --budget` at fractions of its count and
    /// `compact` of its model, in held-out PSNR, Gaussians, bytes and seconds.
    Budget(budget::BudgetArgs),
    /// Where the twin holds and where it breaks: fewer views, pose noise, training scale, a
    /// textureless building and mask noise, each moved alone from a baseline run.
    Stability(stability::StabilityArgs),
    /// A real segmenter's masks: the crack model on the crack photos (IoU, precision / recall
    /// within 2 px by scale and tile, seconds per megapixel) and on the demo building, alone and
    /// through a label-mode twin trained on them.
    Segment(segment::SegmentStudyArgs),
    /// Survey updates run with different settings (`twin update`), from their metrics: held-out
    /// IoU, hull coverage and survey 1's look against wall time, on one chart.
    Update(update::UpdateStudyArgs),
    /// Real photos with stamped damage (issue 42): the crack model's per-photo errors, the
    /// label-mode twin, its fine-tune, the model's errors the twin corrects, change detection
    /// against survey 2 and the measured quantities, all against the stamped truth.
    Real(real::RealStudyArgs),
}

pub fn run(study: Study) -> anyhow::Result<()> {
    match study {
        Study::MaskNoise(args) => mask_noise::run(args),
        Study::Hierarchy(args) => hierarchy::run(args),
        Study::Budget(args) => budget::run(args),
        Study::Stability(args) => stability::run(args),
        Study::Segment(args) => segment::run(args),
        Study::Update(args) => update::run(args),
        Study::Real(args) => real::run(args),
    }
}

/// A study's saved `dir/name` (its JSON), read back for `--replot`.
pub(crate) fn read_saved<T: serde::de::DeserializeOwned>(
    dir: &std::path::Path,
    name: &str,
) -> anyhow::Result<T> {
    use anyhow::Context;
    let path = dir.join(name);
    // Read like any input: a FIFO or a device put in its place is refused, not waited on.
    let bytes = damage_twin::scene::files::read_regular(
        &path,
        damage_twin::scene::limits::MAX_PROJECT_JSON_BYTES,
    )?;
    serde_json::from_slice(&bytes).with_context(|| format!("{} is not a {name}", path.display()))
}

/// Writes `text` to `dir/name` atomically.
pub(crate) fn write_text(dir: &std::path::Path, name: &str, text: &str) -> anyhow::Result<()> {
    use anyhow::Context;
    let path = dir.join(name);
    damage_twin::scene::atomic::write_atomic(&path, |w| {
        std::io::Write::write_all(w, text.as_bytes())
    })
    .with_context(|| format!("writing {}", path.display()))
}
