//! synth is deterministic (same seed, byte-identical files) and its mask noise corrupts exactly
//! the requested fraction of views while `truth/` keeps the clean masks.

mod synth_support;

use std::path::Path;

use damage_twin::damage::DamageClass;
use damage_twin::synth::{self, SynthParams};
use synth_support::files;

fn params(out: &Path, mask_noise: f32) -> SynthParams {
    SynthParams {
        width: 160,
        height: 90,
        views: 4,
        views_survey2: 2,
        sparse_points: 500,
        mask_noise,
        ..SynthParams::demo(out)
    }
}

#[test]
fn same_seed_gives_identical_files_and_mask_noise_only_touches_the_chosen_views() {
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    let clean = tempfile::tempdir().unwrap();
    synth::generate(&params(a.path(), 0.5), &|_, _| {}).unwrap();
    synth::generate(&params(b.path(), 0.5), &|_, _| {}).unwrap();
    synth::generate(&params(clean.path(), 0.0), &|_, _| {}).unwrap();

    let fa = files(a.path());
    let fb = files(b.path());
    // The manifest records the output folder, which differs between the runs.
    let same = |p: &Path| !p.ends_with("truth/manifest.ron");
    assert_eq!(fa.keys().collect::<Vec<_>>(), fb.keys().collect::<Vec<_>>());
    for (path, bytes) in fa.iter().filter(|(p, _)| same(p)) {
        assert!(
            &fb[path] == bytes,
            "{} differs between runs",
            path.display()
        );
    }
    // 3 classes x (masks + truth) x views, images, components, depth, sparse model, manifest.
    assert!(fa.len() > 60, "{} files", fa.len());
    assert!(fa.contains_key(Path::new("survey-2/truth/new-damage/crack/view-000.png")));

    let fc = files(clean.path());
    for survey in ["survey-1", "survey-2"] {
        let views = if survey == "survey-1" { 4 } else { 2 };
        let mut corrupted = 0;
        for v in 0..views {
            let name = synth::view_name(v);
            let mut differs = false;
            for class in DamageClass::ALL {
                let written = Path::new(survey).join("masks").join(class.id()).join(&name);
                let truth = Path::new(survey)
                    .join("truth/masks")
                    .join(class.id())
                    .join(&name);
                // truth/ is the clean mask: identical to the masks of a run without noise.
                assert!(
                    fa[&truth] == fc[&written],
                    "{} is not clean",
                    truth.display()
                );
                differs |= fa[&written] != fa[&truth];
            }
            corrupted += differs as usize;
        }
        assert_eq!(
            corrupted,
            views / 2,
            "{survey}: round(0.5 x {views}) views corrupted"
        );
    }
}

#[test]
fn joint_frame_runs_are_identical_and_keep_survey_1_as_the_same_frame_run_writes_it() {
    let joint = |out: &Path| SynthParams {
        survey2_frame: synth::Survey2Frame::Joint,
        ..params(out, 0.5)
    };
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    let same = tempfile::tempdir().unwrap();
    synth::generate(&joint(a.path()), &|_, _| {}).unwrap();
    synth::generate(&joint(b.path()), &|_, _| {}).unwrap();
    synth::generate(&params(same.path(), 0.5), &|_, _| {}).unwrap();
    let (fa, fb, fs) = (files(a.path()), files(b.path()), files(same.path()));
    assert_eq!(fa.keys().collect::<Vec<_>>(), fb.keys().collect::<Vec<_>>());
    for (path, bytes) in fa
        .iter()
        .filter(|(p, _)| !p.ends_with("truth/manifest.ron"))
    {
        assert!(
            &fb[path] == bytes,
            "{} differs between runs",
            path.display()
        );
        if path.starts_with("survey-1") {
            assert!(
                &fs[path] == bytes,
                "{} differs from the same-frame run",
                path.display()
            );
        }
    }
    assert!(fa.contains_key(Path::new("survey-2/truth/joint_frame.json")));
    assert!(fa.contains_key(Path::new("survey-2/images/new-view-001.png")));
    assert!(fa.contains_key(Path::new("survey-2/images/view-003.png")));
}
