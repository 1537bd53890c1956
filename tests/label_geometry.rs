//! `Targets::label_geometry_steps`: after the switch the label loss no longer moves the
//! geometry, and the label logits keep the steps the full loss gives them.

mod blob_scene;

use blob_scene::{initial_with_labels, labelled_views, max_gap};
use damage_twin::splats::Splats;
use damage_twin::train::spec::{DensifyPolicy, ParamGroups, TrainSpec};
use damage_twin::train::trainer::Trainer;

fn initial() -> Splats {
    initial_with_labels(1)
}

fn spec(rgb_weight: f32, label_weight: f32, label_geometry_steps: Option<u32>) -> TrainSpec {
    let mut spec = TrainSpec::reconstruction(40);
    spec.sh_degree = 1;
    spec.densify = DensifyPolicy::Off;
    spec.targets.rgb_weight = rgb_weight;
    spec.targets.label_weight = label_weight;
    spec.targets.label_pos_weight = 4.0;
    spec.targets.label_geometry_steps = label_geometry_steps;
    spec
}

fn train(spec: TrainSpec) -> Splats {
    let mut trainer = Trainer::new(spec, initial(), labelled_views()).unwrap();
    while !trainer.is_done() {
        let report = trainer.step();
        assert!(report.rolled_back.is_none(), "{report:?}");
    }
    trainer.into_splats()
}

fn max_mean_gap(a: &Splats, b: &Splats) -> f32 {
    a.means
        .iter()
        .zip(&b.means)
        .map(|(p, q)| (*p - *q).abs().max_element())
        .fold(0.0, f32::max)
}

#[test]
fn detached_labels_leave_the_geometry_to_the_photos() {
    let photos_only = train(spec(1.0, 0.0, None));
    let shaped = train(spec(1.0, 1.0, None));
    let detached = train(spec(1.0, 1.0, Some(0)));
    // The label loss moves the geometry when it may...
    let moved = max_mean_gap(&shaped, &photos_only);
    assert!(moved > 1e-3, "the label loss moved no mean: {moved}");
    // ...and, detached from the first step, next to nothing of it reaches the geometry.
    let leaked = max_mean_gap(&detached, &photos_only);
    assert!(
        leaked < 0.01 * moved,
        "detached label loss still moved the means by {leaked} (attached: {moved})"
    );
    // The logits still learn the masks: as far from their start as the attached run's.
    let start = initial();
    let learnt = max_gap(&detached.raw_labels, &start.raw_labels);
    let attached = max_gap(&shaped.raw_labels, &start.raw_labels);
    assert!(
        learnt > 0.5 * attached && learnt > 0.1,
        "logits moved {learnt} detached, {attached} attached"
    );
}

#[test]
fn the_switch_keeps_the_label_logits_steps() {
    // Geometry frozen, labels only: scaling the loss at step 10 must not change the logits'
    // path, since their Adam moments are scaled with it.
    let labels_only = |until| {
        let mut spec = spec(0.0, 1.0, until);
        spec.groups = ParamGroups::LABELS_ONLY;
        train(spec)
    };
    let whole = labels_only(None);
    let switched = labels_only(Some(10));
    let start = initial();
    let travelled = max_gap(&whole.raw_labels, &start.raw_labels);
    let apart = max_gap(&switched.raw_labels, &whole.raw_labels);
    assert!(travelled > 0.1, "the logits did not learn: {travelled}");
    assert!(
        apart < 1e-3 * travelled,
        "the switch changed the logits by {apart} (they travelled {travelled})"
    );
}
