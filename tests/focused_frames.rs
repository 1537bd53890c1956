//! Focused frames (`Rasterizer::set_focus`): a run that trains a few Gaussians reuses each
//! view's projection and depth order of the frozen rest. Against whole frames of the same model:
//! the image (every channel) and the trainable Gaussians' gradients are bit-identical, the
//! frozen ones' gradients zero; the cache is rebuilt whenever its view's camera, the trainable
//! set or the generation changes, and is really reused otherwise. A focused training run gives
//! the same model with the cache as without it, and with Adam's moments for the trainable
//! Gaussians only as with moments for every one.

use damage_twin::raster::{
    FrameFocus, Rasterizer, RenderOutput, RenderSettings, SplatGrads, tile_grid,
};
use damage_twin::scene::{Camera, Mask, RgbImage};
use damage_twin::splats::Splats;
use damage_twin::train::densify::DensifyConfig;
use damage_twin::train::spec::{DensifyPolicy, TrainSpec, TrainView};
use damage_twin::train::trainer::Trainer;
use glam::Vec3;

mod frame_support;
use frame_support::{H, W, bits, camera, labelled_model, seeded_backward};

const LABELS: usize = 3;

/// About a third of the tiles, seeded.
fn active_tiles(seed: u64) -> Vec<bool> {
    let (tx, ty) = tile_grid(W, H);
    let mut rng = fastrand::Rng::with_seed(seed);
    (0..tx * ty).map(|_| rng.f32() < 0.35).collect()
}

/// Moves and recolours the Gaussians `ids` a little, as a training step would.
fn nudge(s: &mut Splats, ids: &[u32], seed: u64) {
    let mut rng = fastrand::Rng::with_seed(seed);
    let k = s.sh_coeffs() * 3;
    for &g in ids {
        let g = g as usize;
        s.means[g] += Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 0.05;
        s.raw_opacities[g] += rng.f32() - 0.5;
        s.sh[g * k] += rng.f32() - 0.5;
        s.raw_labels[g * LABELS] += rng.f32() - 0.5;
    }
}

/// One frame and its backward under `focus` (None: whole), with seeded pixel gradients.
fn frame(
    r: &mut Rasterizer,
    s: &Splats,
    cam: &Camera,
    active: &[bool],
    focus: Option<FrameFocus<'_>>,
) -> (RenderOutput, SplatGrads) {
    let settings = RenderSettings::default();
    r.set_active_tiles(Some(active));
    r.set_focus(focus);
    let mut out = RenderOutput::default();
    r.forward(s, cam, &settings, &mut out);
    let grads = seeded_backward(r, s, cam, &settings, &out, |_| true);
    (out, grads)
}

/// The focused frame equals the whole one: every image channel bit for bit, the trainable
/// Gaussians' gradients bit for bit, and after a cached frame the frozen ones' zero.
fn assert_same(
    focused: &(RenderOutput, SplatGrads),
    whole: &(RenderOutput, SplatGrads),
    trainable: &[u32],
    cached: bool,
    what: &str,
) {
    let (fo, fg) = focused;
    let (wo, wg) = whole;
    assert_eq!(bits(&fo.color), bits(&wo.color), "{what}: colour");
    assert_eq!(bits(&fo.alpha), bits(&wo.alpha), "{what}: alpha");
    assert_eq!(bits(&fo.depth), bits(&wo.depth), "{what}: depth");
    assert_eq!(bits(&fo.labels), bits(&wo.labels), "{what}: labels");
    let k = 48;
    let mut is_trainable = vec![false; fg.v_means.len()];
    for &g in trainable {
        is_trainable[g as usize] = true;
    }
    let mut used = 0;
    for (g, &t) in is_trainable.iter().enumerate() {
        let sh = |gr: &SplatGrads| bits(&gr.v_sh[g * k..(g + 1) * k]);
        let lab = |gr: &SplatGrads| bits(&gr.v_raw_labels[g * LABELS..(g + 1) * LABELS]);
        if t {
            assert_eq!(fg.v_means[g], wg.v_means[g], "{what}: mean gradient of {g}");
            assert_eq!(
                fg.v_log_scales[g], wg.v_log_scales[g],
                "{what}: scale gradient of {g}"
            );
            assert_eq!(
                fg.v_rotations[g], wg.v_rotations[g],
                "{what}: rotation gradient of {g}"
            );
            assert_eq!(
                fg.v_raw_opacities[g].to_bits(),
                wg.v_raw_opacities[g].to_bits(),
                "{what}: opacity gradient of {g}"
            );
            assert_eq!(sh(fg), sh(wg), "{what}: SH gradient of {g}");
            assert_eq!(lab(fg), lab(wg), "{what}: label gradient of {g}");
            assert_eq!(fg.visible[g], wg.visible[g], "{what}: visibility of {g}");
            assert_eq!(
                fg.v_means2d_norm[g].to_bits(),
                wg.v_means2d_norm[g].to_bits()
            );
            used += usize::from(wg.v_means[g] != Vec3::ZERO);
        } else if cached {
            assert_eq!(
                fg.v_means[g],
                Vec3::ZERO,
                "{what}: frozen {g} got a gradient"
            );
            assert!(fg.v_sh[g * k..(g + 1) * k].iter().all(|&v| v == 0.0));
        }
    }
    assert!(
        used > 20,
        "{what}: only {used} trainable Gaussians had gradients"
    );
}

#[test]
fn cached_frames_match_whole_frames_and_are_rebuilt_when_stale() {
    let mut s = labelled_model(3000, 5, LABELS);
    let (cam_a, cam_b) = (
        camera(Vec3::new(0.3, -0.2, 0.0)),
        camera(Vec3::new(-0.5, 0.1, 0.4)),
    );
    let active = active_tiles(3);
    let trainable: Vec<u32> = (0..s.len() as u32).filter(|g| g % 7 == 0).collect();
    let mut focused = Rasterizer::new();
    let focus = |view, trainable, generation| {
        Some(FrameFocus {
            trainable,
            view,
            generation,
        })
    };
    let check = |r: &mut Rasterizer,
                 s: &Splats,
                 cam: &Camera,
                 f: Option<FrameFocus<'_>>,
                 cached: bool,
                 what: &str| {
        let trainable = f.map(|f| f.trainable.to_vec()).unwrap_or_default();
        let got = frame(r, s, cam, &active, f);
        assert_eq!(r.last_frame_cached(), cached, "{what}: cached or not");
        let whole = frame(&mut Rasterizer::new(), s, cam, &active, None);
        assert_same(&got, &whole, &trainable, cached, what);
    };
    // First frame of view 0 is rendered whole; the next ones reuse its frozen part.
    check(
        &mut focused,
        &s,
        &cam_a,
        focus(0, &trainable, 0),
        false,
        "view 0, first",
    );
    nudge(&mut s, &trainable, 1);
    check(
        &mut focused,
        &s,
        &cam_a,
        focus(0, &trainable, 0),
        true,
        "view 0, trained",
    );
    check(
        &mut focused,
        &s,
        &cam_b,
        focus(1, &trainable, 0),
        false,
        "view 1, first",
    );
    nudge(&mut s, &trainable, 2);
    check(
        &mut focused,
        &s,
        &cam_b,
        focus(1, &trainable, 0),
        true,
        "view 1, trained",
    );
    check(
        &mut focused,
        &s,
        &cam_a,
        focus(0, &trainable, 0),
        true,
        "view 0 again",
    );
    // Another camera under view 0's index: rebuilt.
    check(
        &mut focused,
        &s,
        &cam_b,
        focus(0, &trainable, 0),
        false,
        "view 0, moved camera",
    );
    // Another trainable set: every cache rebuilt.
    let other: Vec<u32> = (0..s.len() as u32).filter(|g| g % 5 == 1).collect();
    check(
        &mut focused,
        &s,
        &cam_a,
        focus(1, &other, 0),
        false,
        "new trainable set",
    );
    nudge(&mut s, &other, 3);
    check(
        &mut focused,
        &s,
        &cam_a,
        focus(1, &other, 0),
        true,
        "new set, trained",
    );
    // A frozen Gaussian changed: the caller's new generation rebuilds the cache.
    let frozen = [2u32, 3, 4, 8, 9];
    nudge(&mut s, &frozen, 4);
    check(
        &mut focused,
        &s,
        &cam_a,
        focus(1, &other, 1),
        false,
        "new generation",
    );
    // Without the new generation the cache is really reused: the changed frozen Gaussians
    // still render as they were (the generation is what keeps it honest).
    nudge(&mut s, &frozen, 5);
    let stale = frame(&mut focused, &s, &cam_a, &active, focus(1, &other, 1));
    assert!(focused.last_frame_cached());
    let whole = frame(&mut Rasterizer::new(), &s, &cam_a, &active, None);
    assert_ne!(
        bits(&stale.0.color),
        bits(&whole.0.color),
        "the cache was not used"
    );
    // Plain frames after focused ones: whole again.
    let plain = frame(&mut focused, &s, &cam_a, &active, None);
    assert!(!focused.last_frame_cached());
    assert_eq!(bits(&plain.0.color), bits(&whole.0.color));
}

/// Views of `target` from three cameras, each with a loss region (a rectangle) and label
/// masks (the target's label channels above one half).
fn views(target: &Splats) -> Vec<TrainView> {
    let eyes = [
        Vec3::new(0.3, -0.2, 0.0),
        Vec3::new(-0.5, 0.1, 0.4),
        Vec3::new(0.1, 0.4, -0.3),
    ];
    eyes.iter()
        .enumerate()
        .map(|(i, &eye)| {
            let cam = camera(eye);
            let out = damage_twin::raster::render(target, &cam, &RenderSettings::default());
            let mut region = Mask::empty(W, H);
            let (x0, y0) = (20 + 30 * i as u32, 15 + 10 * i as u32);
            for y in y0..y0 + 40 {
                for x in x0..x0 + 50 {
                    region.data[(y * W + x) as usize] = 1;
                }
            }
            let labels = (0..LABELS)
                .map(|k| Mask {
                    width: W,
                    height: H,
                    data: (0..(W * H) as usize)
                        .map(|p| u8::from(out.labels[p * LABELS + k] > 0.5))
                        .collect(),
                })
                .collect();
            TrainView {
                name: format!("view-{i}"),
                camera: cam,
                image: RgbImage {
                    width: W,
                    height: H,
                    data: out.color,
                },
                labels,
                region: Some(region),
                light: None,
            }
        })
        .collect()
}

/// A focused run's target, its start (the target with every fourth Gaussian from `first`
/// nudged by `seed`) and the trainable mask (those Gaussians).
fn focused_start(first: usize, seed: u64) -> (Splats, Splats, Vec<bool>) {
    let target = labelled_model(2000, 21, LABELS);
    let mut start = target.clone();
    let trainable: Vec<bool> = (0..start.len()).map(|g| g % 4 == first).collect();
    let ids: Vec<u32> = (0..start.len() as u32)
        .filter(|&g| trainable[g as usize])
        .collect();
    nudge(&mut start, &ids, seed);
    (target, start, trainable)
}

/// The spec of a focused run of `iterations` steps on `trainable`, with the labels in the loss.
fn focused_test_spec(iterations: u32, trainable: Vec<bool>) -> TrainSpec {
    let mut spec = TrainSpec::reconstruction(iterations);
    spec.trainable = Some(trainable);
    spec.sh_ramp_every = 0;
    spec.eval_every = 0;
    spec.targets.label_weight = 0.5;
    spec
}

/// Steps `a` and `b` to the end side by side: every loss the same bits, nothing rolled back.
fn train_side_by_side(a: &mut Trainer, b: &mut Trainer, what: &str) {
    while !a.is_done() {
        let (x, y) = (a.step(), b.step());
        assert_eq!(
            x.loss.to_bits(),
            y.loss.to_bits(),
            "{what}: step {}",
            x.step
        );
        assert!(x.rolled_back.is_none());
    }
}

#[test]
fn a_focused_run_trains_the_same_with_and_without_the_frozen_cache() {
    let (target, start, trainable) = focused_start(0, 9);
    let spec = focused_test_spec(24, trainable);
    let views = views(&target);
    let mut cached = Trainer::new(spec.clone(), start.clone(), views.clone()).unwrap();
    let mut whole = Trainer::new(spec, start.clone(), views).unwrap();
    whole.set_frozen_cache(false);
    train_side_by_side(&mut cached, &mut whole, "frozen cache");
    let (a, b) = (cached.splats(), whole.splats());
    assert_ne!(a.means, start.means, "training moved something");
    assert_eq!(a, b, "the models differ");
}

/// Adam's moments for the trainable Gaussians only (the default) against moments for every
/// Gaussian (the layout before): the same losses and model bit for bit, fine-tuned as is and
/// with density control (children appended, prunes, an opacity reset) in the run.
#[test]
fn a_focused_run_trains_the_same_with_moments_for_the_trainable_only() {
    let (target, start, trainable) = focused_start(1, 10);
    let views = views(&target);
    let densify = DensifyConfig {
        start: 4,
        stop: 30,
        every: 8,
        grad_threshold: 1e-6,
        min_opacity: 0.05,
        opacity_reset_every: 20,
        ..DensifyConfig::default()
    };
    for policy in [DensifyPolicy::Off, DensifyPolicy::Adaptive(densify)] {
        let mut spec = focused_test_spec(32, trainable.clone());
        spec.densify = policy.clone();
        let mut listed = Trainer::new(spec.clone(), start.clone(), views.clone()).unwrap();
        let mut every = Trainer::new(spec, start.clone(), views.clone()).unwrap();
        every.keep_moments_for_every_gaussian();
        train_side_by_side(&mut listed, &mut every, &format!("{policy:?}"));
        let (a, b) = (listed.splats(), every.splats());
        assert_ne!(a.means, start.means, "training moved something");
        if let DensifyPolicy::Adaptive(_) = policy {
            assert_ne!(a.len(), start.len(), "density control changed the count");
        }
        assert_eq!(a, b, "{policy:?}: the models differ");
    }
}
