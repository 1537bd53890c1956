//! synth's ground truth agrees with its poses: known 3D damage points, projected through the
//! COLMAP cameras read back from disk, land in the written masks; survey 2's new-damage masks are
//! non-empty exactly in the views that see new damage.

mod synth_support;

use std::path::Path;

use damage_twin::synth::{self, SynthParams, World};
use synth_support::{damage_points_in_masks, new_damage_masks_where_seen, read_cameras};

fn small_params(out: &Path) -> SynthParams {
    SynthParams {
        width: 320,
        height: 180,
        views: 4,
        views_survey2: 7,
        sparse_points: 2000,
        ..SynthParams::demo(out)
    }
}

#[test]
fn damage_points_project_into_the_written_masks_and_new_damage_is_where_it_is_seen() {
    let dir = tempfile::tempdir().unwrap();
    let params = small_params(dir.path());
    synth::generate(&params, &|_, _| {}).expect("synth runs");
    let world = World::new(&params);

    // Poses and masks agree: every visible damage point hits its class within one pixel.
    let s1 = dir.path().join("survey-1");
    assert_eq!(read_cameras(&s1).len(), params.views);
    let points = world.damage_points(1, 0.02, false);
    let (checked, missed) = damage_points_in_masks(&s1, &world, &points);
    eprintln!("visible damage points per class {checked:?}, missed {missed:?}");
    assert!(
        checked[0] > 200 && checked[1] > 200,
        "too few visible points: {checked:?}"
    );
    for k in 0..3 {
        // Measured: misses come only from points on spall/crack borders where the 0-footprint
        // classification and the pixel-footprint one differ; well under 1 %.
        assert!(
            missed[k] * 100 <= checked[k],
            "class {k}: {} of {} missed",
            missed[k],
            checked[k]
        );
    }

    // New damage: masks non-empty exactly where new-damage points are visible.
    let s2 = dir.path().join("survey-2");
    assert_eq!(read_cameras(&s2).len(), params.views_survey2);
    let new_points = world.damage_points(2, 0.01, true);
    assert!(!new_points.is_empty());
    let (seeing, blind) = new_damage_masks_where_seen(&s2, &world, &new_points);
    assert!(
        seeing > 0 && blind > 0,
        "the path must include views with and without new damage"
    );
}
