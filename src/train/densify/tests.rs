//! Behaviour of adaptive density control against 3DGS's semantics.

use super::*;
use crate::splats::model::logit;

const EXTENT: f32 = 10.0; // clone/split boundary 0.1, world prune limit 1.0

/// Gaussians with given max scales and opacities, SH degree 1, 2 label channels.
fn model(scales: &[f32], opacities: &[f32]) -> Splats {
    let mut s = Splats::empty(1, 2);
    for (g, (&sc, &op)) in scales.iter().zip(opacities).enumerate() {
        let sh: Vec<f32> = (0..12).map(|k| (g * 100 + k) as f32).collect();
        s.push(
            Vec3::new(g as f32, 0.0, 0.0),
            Vec3::new(sc.ln(), (sc * 0.5).ln(), (sc * 0.25).ln()),
            Quat::from_rotation_z(0.3 * g as f32),
            logit(op),
            &sh,
            &[g as f32, -(g as f32)],
            100 + g as u64,
            3,
        );
    }
    s
}

/// Feeds `steps` steps of the given per-Gaussian gradient norms, all visible at radius `r`.
fn feed(d: &mut Densifier, grads: &[f32], r: u32, steps: usize) {
    let radii = vec![r; grads.len()];
    for _ in 0..steps {
        d.accumulate(grads, &radii);
    }
}

fn no_reset() -> DensifyConfig {
    DensifyConfig {
        opacity_reset_every: 0,
        ..DensifyConfig::default()
    }
}

#[test]
fn clone_copies_small_high_gradient_gaussians_with_new_ids() {
    let mut s = model(&[0.05, 0.05], &[0.5, 0.5]);
    let mut adam = Adam::new(&s);
    let mut d = Densifier::new(no_reset(), 2);
    feed(&mut d, &[3e-4, 1e-4], 5, 4);
    let r = d.densify_and_prune(&mut s, &mut adam, EXTENT, false);
    assert_eq!((r.cloned, r.split, r.pruned), (1, 0, 0));
    assert_eq!(s.len(), 3);
    assert_eq!(s.means[2], s.means[0]);
    assert_eq!(s.log_scales[2], s.log_scales[0]);
    assert_eq!(s.sh_of(2), s.sh_of(0));
    assert_eq!(s.labels_of(2), s.labels_of(0));
    assert_eq!(s.meta.ids, vec![100, 101, 102]);
    assert_eq!(s.meta.survey[2], 3);
    assert!(!s.meta.frozen[2]);
    assert_eq!(adam.len(), 3);
    s.check_lengths().unwrap();
}

#[test]
fn split_divides_scale_by_1_6_and_keeps_opacity() {
    let mut s = model(&[0.5], &[0.7]);
    let mut adam = Adam::new(&s);
    let mut d = Densifier::new(no_reset(), 1);
    feed(&mut d, &[1e-3], 5, 1);
    let parent = s.clone();
    let r = d.densify_and_prune(&mut s, &mut adam, EXTENT, false);
    assert_eq!((r.cloned, r.split, r.pruned), (0, 1, 0));
    assert_eq!(s.len(), 2, "the parent is replaced by two children");
    for g in 0..2 {
        let shrink = parent.log_scales[0] - s.log_scales[g];
        assert!((shrink - Vec3::splat(1.6f32.ln())).abs().max_element() < 1e-6);
        assert_eq!(s.raw_opacities[g], parent.raw_opacities[0]);
        assert_eq!(s.rotations[g], parent.rotations[0]);
        assert_eq!(s.sh_of(g), parent.sh_of(0));
        assert_ne!(s.means[g], parent.means[0]);
    }
    assert_eq!(s.meta.ids, vec![101, 102], "children get fresh ids");
    assert_eq!(adam.len(), 2);
}

#[test]
fn split_children_are_drawn_from_the_rotated_parent_gaussian() {
    // Many parents with an anisotropic scale rotated 90° about z: the children's spread along
    // world x must match the parent's local y scale.
    let n = 2000;
    let mut s = Splats::empty(0, 0);
    let rot = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
    for g in 0..n {
        s.push(
            Vec3::ZERO,
            Vec3::new(1.0f32.ln(), 0.2f32.ln(), 0.2f32.ln()),
            rot,
            0.0,
            &[0.0; 3],
            &[],
            g as u64,
            0,
        );
    }
    let mut adam = Adam::new(&s);
    let mut d = Densifier::new(no_reset(), n);
    feed(&mut d, &vec![1.0; n], 5, 1);
    d.densify_and_prune(&mut s, &mut adam, EXTENT, false);
    let var =
        |f: fn(Vec3) -> f32| s.means.iter().map(|&m| f(m).powi(2)).sum::<f32>() / s.len() as f32;
    let (sx, sy) = (var(|m| m.x).sqrt(), var(|m| m.y).sqrt());
    // Sampling error of a standard deviation from 4000 samples: ~1.1 %; allow 5 %.
    assert!((sx - 0.2).abs() < 0.01, "x spread {sx}");
    assert!((sy - 1.0).abs() < 0.05, "y spread {sy}");
}

#[test]
fn gradient_is_averaged_over_visible_steps_only() {
    let mut s = model(&[0.05], &[0.5]);
    let mut adam = Adam::new(&s);
    let mut d = Densifier::new(no_reset(), 1);
    // Visible once with 3e-4, invisible (radius 0) ten times with a large value that must be ignored.
    d.accumulate(&[3e-4], &[4]);
    for _ in 0..10 {
        d.accumulate(&[1.0], &[0]);
    }
    assert_eq!(d.mean_grads(), vec![3e-4]);
    // Visible 3 more times with 0: mean 7.5e-5 < threshold.
    feed(&mut d, &[0.0], 4, 3);
    let r = d.densify_and_prune(&mut s, &mut adam, EXTENT, false);
    assert_eq!(r.cloned + r.split, 0);
    assert_eq!(
        d.mean_grads(),
        vec![0.0],
        "statistics are zeroed after densifying"
    );
}

#[test]
fn prune_removes_transparent_and_after_reset_oversized_gaussians() {
    // 0: transparent; 1: too large in the world; 2: large on screen; 3: fine.
    let mut s = model(&[0.05, 2.0, 0.05, 0.05], &[0.004, 0.5, 0.5, 0.5]);
    let mut adam = Adam::new(&s);
    let mut d = Densifier::new(no_reset(), 4);
    d.accumulate(&[0.0; 4], &[3, 3, 25, 3]);
    let r = d
        .clone()
        .densify_and_prune(&mut s.clone(), &mut adam.clone(), EXTENT, false);
    assert_eq!(r.pruned, 1, "before the first reset only opacity prunes");
    let mut default_size = s.clone();
    let r = d
        .clone()
        .densify_and_prune(&mut default_size, &mut adam.clone(), EXTENT, true);
    assert_eq!(
        r.pruned, 2,
        "by default the screen radius does not prune (3DGS as it runs)"
    );
    assert_eq!(default_size.meta.ids, vec![102, 103]);
    d.config.max_screen_size = Some(20.0);
    let r = d.densify_and_prune(&mut s, &mut adam, EXTENT, true);
    assert_eq!(r.pruned, 3);
    assert_eq!(s.meta.ids, vec![103]);
    assert_eq!(adam.len(), 1);
}

#[test]
fn frozen_gaussians_are_never_cloned_split_pruned_or_reset() {
    let mut s = model(&[0.05, 0.5, 0.05, 0.05], &[0.5, 0.5, 0.001, 0.9]);
    s.meta.frozen = vec![true; 4];
    let before = s.clone();
    let mut adam = Adam::new(&s);
    let mut d = Densifier::new(DensifyConfig::default(), 4);
    feed(&mut d, &[1.0; 4], 30, 3);
    let r = d.densify_and_prune(&mut s, &mut adam, EXTENT, true);
    assert_eq!((r.cloned, r.split, r.pruned), (0, 0, 0));
    d.reset_opacity(&mut s, &mut adam);
    assert_eq!(s, before);
}

#[test]
fn opacity_reset_caps_at_0_01_and_keeps_lower_values() {
    let mut s = model(&[0.05, 0.05], &[0.9, 0.004]);
    let low = s.raw_opacities[1];
    let mut adam = Adam::new(&s);
    let d = Densifier::new(DensifyConfig::default(), 2);
    d.reset_opacity(&mut s, &mut adam);
    assert!((sigmoid(s.raw_opacities[0]) - 0.01).abs() < 1e-6);
    assert_eq!(s.raw_opacities[1], low);
}

#[test]
fn schedule_densifies_after_start_every_interval_before_stop_and_resets_periodically() {
    let config = DensifyConfig {
        start: 5,
        stop: 30,
        every: 5,
        opacity_reset_every: 12,
        ..DensifyConfig::default()
    };
    let mut s = model(&[0.05], &[0.9]);
    let mut adam = Adam::new(&s);
    let mut d = Densifier::new(config, 1);
    let mut densified = Vec::new();
    let mut resets = Vec::new();
    for step in 1..=40 {
        let n = s.len();
        d.accumulate(&vec![0.0; n], &vec![1; n]);
        let r = d.after_step(step, &mut s, &mut adam, EXTENT);
        if r.densified {
            densified.push(step);
        }
        if r.opacity_reset {
            resets.push(step);
        }
    }
    assert_eq!(densified, vec![10, 15, 20, 25]);
    assert_eq!(resets, vec![12, 24]);
}

#[test]
fn budget_caps_the_count_and_prefers_high_gradients() {
    let mut s = model(&[0.05; 6], &[0.5; 6]);
    let mut adam = Adam::new(&s);
    let config = DensifyConfig {
        budget: Some(8),
        ..no_reset()
    };
    let mut d = Densifier::new(config, 6);
    feed(&mut d, &[3e-4, 9e-4, 5e-4, 8e-4, 1e-4, 7e-4], 3, 1);
    let r = d.densify_and_prune(&mut s, &mut adam, EXTENT, false);
    assert_eq!(r.cloned, 2);
    assert_eq!(s.len(), 8);
    // Clones of Gaussians 1 and 3 (the two highest gradients), in index order.
    assert_eq!(s.means[6], s.means[1]);
    assert_eq!(s.means[7], s.means[3]);
}

#[test]
fn densification_is_deterministic_for_a_seed() {
    let run = |seed: u64| {
        let mut s = model(&[0.5, 0.05, 0.8], &[0.5; 3]);
        let mut adam = Adam::new(&s);
        let mut d = Densifier::new(DensifyConfig { seed, ..no_reset() }, 3);
        feed(&mut d, &[1e-3; 3], 3, 1);
        d.densify_and_prune(&mut s, &mut adam, EXTENT, false);
        s
    };
    assert_eq!(run(4), run(4));
    assert_ne!(run(4).means, run(5).means);
}

#[test]
fn adam_moments_follow_clones_and_pruning() {
    let mut s = model(&[0.05, 0.05, 0.05], &[0.5, 0.5, 0.001]);
    let mut adam = Adam::new(&s);
    // Give every Gaussian distinct opacity moments via one step with gradient = index + 1.
    let n = s.len();
    let v3 = vec![Vec3::ZERO; n];
    let v4 = vec![glam::Vec4::ZERO; n];
    let op: Vec<f32> = (0..n).map(|g| g as f32 + 1.0).collect();
    let sh = vec![0.0; s.sh.len()];
    let lb = vec![0.0; s.raw_labels.len()];
    let grads = super::super::adam::ParamGrads {
        v_means: &v3,
        v_log_scales: &v3,
        v_rotations: &v4,
        v_raw_opacities: &op,
        v_sh: &sh,
        v_raw_labels: &lb,
    };
    adam.step(&mut s, &grads, &[0.0; 7], &Default::default(), None);
    let mut d = Densifier::new(no_reset(), n);
    feed(&mut d, &[1e-3, 0.0, 0.0], 3, 1);
    d.densify_and_prune(&mut s, &mut adam, EXTENT, false);
    // Gaussian 2 (transparent) pruned; 0 cloned to the end: [0, 1, clone of 0].
    assert_eq!(s.meta.ids, vec![100, 101, 103]);
    let m = adam.moments(ParamGroup::RawOpacities);
    assert!(
        (m.0[0] - 0.1).abs() < 1e-7 && (m.0[1] - 0.2).abs() < 1e-7,
        "{:?}",
        m.0
    );
    assert_eq!(m.0[2], 0.0, "a new Gaussian starts with zero moments");
}
