//! `scene::ViewCache` (`Dataset::keep_loaded_views`): a kept view is the fresh load, bit for bit.
//! Here rather than beside the cache because it makes its survey with `synth`, a layer above
//! `scene`.

use std::path::PathBuf;

use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{Dataset, ImageScale, LoadedView, MaskFolder, MaskSource};

/// A small synthetic survey (four views of the demo building at 96×54, with damage masks
/// and truth masks), and the tempdir holding it.
fn survey() -> (tempfile::TempDir, Dataset) {
    let dir = tempfile::tempdir().expect("temp dir");
    let params = damage_twin::synth::params::SynthParams {
        width: 96,
        height: 54,
        views: 4,
        surveys: 1,
        sparse_points: 500,
        ..damage_twin::synth::params::SynthParams::demo(dir.path())
    };
    damage_twin::synth::generate::generate(&params, &|_, _| {}).expect("synth");
    let root: PathBuf = dir.path().join("survey-1");
    let dataset = Dataset::open(&root, &OpenOptions::default()).expect("opens");
    (dir, dataset)
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn assert_same_view(got: &LoadedView, want: &LoadedView, what: &str) {
    assert_eq!(got.name, want.name, "{what}");
    assert_eq!(got.camera, want.camera, "{what}: camera");
    assert_eq!(
        (got.image.width, got.image.height),
        (want.image.width, want.image.height),
        "{what}: size"
    );
    assert!(
        bits(&got.image.data) == bits(&want.image.data),
        "{what}: photo"
    );
    assert_eq!(got.masks, want.masks, "{what}: masks");
    assert_eq!(got.ignore, want.ignore, "{what}: ignore mask");
}

#[test]
fn a_kept_view_is_the_fresh_load_bit_for_bit() {
    let (_dir, fresh) = survey();
    assert!(fresh.view_cache.is_none(), "off unless asked");
    let mut kept = fresh.clone();
    kept.keep_loaded_views();
    let own = fresh.masks.clone().expect("the survey has masks");
    let truth = MaskFolder::truth(&fresh.root);
    assert!(truth.is_available());
    let cache = kept.view_cache.clone().expect("on");
    let (half, quarter) = (ImageScale::Factor(2), ImageScale::Factor(4));
    for index in 0..fresh.views.len() {
        // Masks alone at a scale no whole view was loaded at, then whole views (twice:
        // read, then kept), then masks at the whole views' scale.
        for round in 0..2 {
            let (camera, masks) = kept.load_view_masks(index, own.as_ref(), quarter).unwrap();
            let want = fresh.load_view_masks(index, own.as_ref(), quarter).unwrap();
            assert_eq!((camera, masks), want, "view {index} masks, round {round}");
        }
        for scale in [ImageScale::Factor(1), half] {
            for round in 0..2 {
                let got = kept.load_view(index, scale).unwrap();
                let want = fresh.load_view(index, scale).unwrap();
                assert_same_view(
                    &got,
                    &want,
                    &format!("view {index} at {scale:?}, round {round}"),
                );
            }
        }
        let got = kept.load_view_masks(index, own.as_ref(), half).unwrap();
        assert_eq!(
            got,
            fresh.load_view_masks(index, own.as_ref(), half).unwrap()
        );
        assert_eq!(
            kept.load_view_ignore(index, half).unwrap(),
            fresh.load_view_ignore(index, half).unwrap()
        );
        // Another mask source is read, never kept or served from the kept views.
        let before = cache.len();
        let got = kept.load_view_masks(index, &truth, half).unwrap();
        assert_eq!(got, fresh.load_view_masks(index, &truth, half).unwrap());
        assert_eq!(cache.len(), before, "the truth masks are not kept");
    }
    // Per view: the masks at a quarter, the whole views at full and half scale.
    assert_eq!(cache.len(), 3 * fresh.views.len());
}
