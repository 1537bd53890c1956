//! `synth --structure bridge`: a small bridge is deterministic for a seed, its masks and depth agree
//! with its known 3D damage through the written cameras, survey 2's new damage is where it is
//! seen and only on the spans `truth/bridge.json` names, the drone strips see every span from
//! both sides and from under the deck, and bad knobs are refused with one line.

mod synth_support;

use std::path::Path;
use std::process::Command;

use damage_twin::synth::bridge::{CLEARANCE, SIDE_PLANE, SPAN, girder_bottom, span_of};
use damage_twin::synth::{self, SynthParams, World};
use glam::Vec3;
use synth_support::{damage_points_in_masks, files, new_damage_masks_where_seen, visible};

fn small_bridge(out: &Path, spans: u32, views: usize) -> SynthParams {
    SynthParams {
        width: 320,
        height: 180,
        views,
        views_survey2: views / 2,
        sparse_points: 2000,
        ..SynthParams::bridge(out, spans)
    }
}

#[test]
fn bridge_masks_and_depth_agree_with_the_known_damage_and_new_damage_is_on_the_changed_spans() {
    let dir = tempfile::tempdir().unwrap();
    let params = small_bridge(dir.path(), 3, 40);
    let output = synth::generate(&params, &|_, _| {}).expect("synth runs");
    assert_eq!(output.surveys.len(), 2);
    let world = World::new(&params);

    let s1 = dir.path().join("survey-1");
    let points = world.damage_points(1, 0.02, false);
    let (checked, missed) = damage_points_in_masks(&s1, &world, &points);
    eprintln!("visible damage points per class {checked:?}, missed {missed:?}");
    assert!(
        checked.iter().all(|&n| n > 100),
        "too few visible points: {checked:?}"
    );
    for k in 0..3 {
        assert!(
            missed[k] * 100 <= checked[k],
            "class {k}: {} of {} missed",
            missed[k],
            checked[k]
        );
    }
    // Every span carries damage on each side in survey 1.
    for span in 0..3 {
        for side in [-1.0f32, 1.0] {
            let n = points
                .iter()
                .filter(|p| span_of(p.position.x, 3) == span && p.position.y * side > 0.0)
                .count();
            assert!(n > 0, "span {span} side {side}: no damage");
        }
    }

    let s2 = dir.path().join("survey-2");
    let new_points = world.damage_points(2, 0.01, true);
    let layout: serde_json::Value =
        serde_json::from_slice(&std::fs::read(s2.join("truth/bridge.json")).unwrap()).unwrap();
    let changed: Vec<u32> = layout["changed_spans"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as u32)
        .collect();
    assert_eq!(changed, world.changed_spans);
    assert!(!changed.is_empty() && changed.len() < 3, "{changed:?}");
    assert!(!new_points.is_empty());
    for p in &new_points {
        let span = span_of(p.position.x, 3);
        assert!(
            changed.contains(&span),
            "new damage at {} on span {span}",
            p.position
        );
    }
    let (seeing, blind) = new_damage_masks_where_seen(&s2, &world, &new_points);
    assert!(seeing > 0 && blind > 0, "seeing {seeing}, blind {blind}");
}

/// Survey-1 cameras of `world` that see surface point `p`.
fn seen_by(world: &World, params: &SynthParams, p: Vec3) -> usize {
    world
        .cameras(params, 1)
        .iter()
        .filter(|cam| visible(cam, world, p).is_some())
        .count()
}

#[test]
fn the_default_strips_see_every_span_from_both_sides_and_from_under_the_deck() {
    // The default bridge's cameras (no rendering): 6 spans, 360 views.
    let params = SynthParams::bridge("unused", 6);
    let world = World::new(&params);
    assert_eq!(world.cameras(&params, 1).len(), 360);
    assert_eq!(world.cameras(&params, 2).len(), 120);
    for span in 0..6 {
        let x = (span as f32 + 0.5) * SPAN;
        let front = seen_by(
            &world,
            &params,
            Vec3::new(x, -SIDE_PLANE, girder_bottom() + 0.6),
        );
        let back = seen_by(
            &world,
            &params,
            Vec3::new(x, SIDE_PLANE, girder_bottom() + 0.6),
        );
        // The soffit between the two inner girders, seen only from under the deck.
        let soffit = seen_by(&world, &params, Vec3::new(x, 0.0, CLEARANCE));
        eprintln!("span {span}: girder seen by {front} (front), {back} (back); soffit by {soffit}");
        assert!(front >= 8 && back >= 8 && soffit >= 3, "span {span}");
    }
    let pier = seen_by(&world, &params, Vec3::new(SPAN, -SIDE_PLANE, 2.0));
    assert!(pier >= 5, "pier 1's column seen by {pier}");
}

#[test]
fn same_seed_gives_identical_bridge_files_and_another_seed_other_damage() {
    let [a, b, c] = [(); 3].map(|_| tempfile::tempdir().unwrap());
    let tiny = |out: &Path, seed: u64| SynthParams {
        width: 160,
        height: 90,
        views: 6,
        views_survey2: 3,
        sparse_points: 500,
        seed,
        ..SynthParams::bridge(out, 2)
    };
    for (dir, seed) in [(&a, 7), (&b, 7), (&c, 8)] {
        synth::generate(&tiny(dir.path(), seed), &|_, _| {}).unwrap();
    }
    let (fa, fb, fc) = (files(a.path()), files(b.path()), files(c.path()));
    assert_eq!(fa.keys().collect::<Vec<_>>(), fb.keys().collect::<Vec<_>>());
    assert!(fa.keys().any(|p| p.ends_with("survey-2/truth/bridge.json")));
    for (path, bytes) in fa
        .iter()
        .filter(|(p, _)| !p.ends_with("truth/manifest.ron"))
    {
        assert!(
            &fb[path] == bytes,
            "{} differs between runs",
            path.display()
        );
    }
    let quantities = Path::new("survey-1/truth/quantities.json");
    assert_ne!(fa[quantities], fc[quantities], "another seed, other damage");
}

#[test]
fn bad_bridge_knobs_are_refused_with_one_line() {
    let out = tempfile::tempdir().unwrap();
    let target = out.path().join("synth");
    let cases: [(&[&str], &str); 4] = [
        (&["--structure", "bridge", "--spans", "0"], "--spans"),
        (&["--structure", "bridge", "--spans", "65"], "--spans"),
        (&["--spans", "3"], "--spans"),
        (&["--structure", "bridge", "--views", "0"], "view"),
    ];
    for (args, needle) in cases {
        let run = Command::new(env!("CARGO_BIN_EXE_damage-twin"))
            .arg("synth")
            .arg("--out")
            .arg(&target)
            .args(args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{args:?} accepted");
        assert_eq!(stderr.trim().lines().count(), 1, "{args:?}: {stderr}");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
        assert!(!target.join("survey-1").exists(), "{args:?} wrote files");
    }
}
