//! Adam against torch's: its steps, frozen and invisible Gaussians, disabled groups, growth and
//! pruning, and the position schedule.

use super::*;
use glam::Quat;

fn model(n: usize) -> Splats {
    let mut s = Splats::empty(1, 2);
    for g in 0..n {
        s.push(
            Vec3::splat(g as f32),
            Vec3::ZERO,
            Quat::IDENTITY,
            0.0,
            &[0.5; 12],
            &[0.0; 2],
            g as u64,
            0,
        );
    }
    s
}

struct Grads {
    v3: Vec<Vec3>,
    v4: Vec<Vec4>,
    op: Vec<f32>,
    sh: Vec<f32>,
    lb: Vec<f32>,
}

impl Grads {
    fn constant(s: &Splats, v: f32) -> Grads {
        Grads {
            v3: vec![Vec3::splat(v); s.len()],
            v4: vec![Vec4::splat(v); s.len()],
            op: vec![v; s.len()],
            sh: vec![v; s.sh.len()],
            lb: vec![v; s.raw_labels.len()],
        }
    }
    fn view(&self) -> ParamGrads<'_> {
        ParamGrads {
            v_means: &self.v3,
            v_log_scales: &self.v3,
            v_rotations: &self.v4,
            v_raw_opacities: &self.op,
            v_sh: &self.sh,
            v_raw_labels: &self.lb,
        }
    }
}

/// torch.optim.Adam on one scalar, in f64.
fn reference(p0: f64, grads: &[f64], lr: f64) -> f64 {
    let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-15f64);
    let (mut p, mut m, mut v) = (p0, 0.0, 0.0);
    for (t, &g) in grads.iter().enumerate() {
        let t = t as i32 + 1;
        m = b1 * m + (1.0 - b1) * g;
        v = b2 * v + (1.0 - b2) * g * g;
        let denom = v.sqrt() / (1.0 - b2.powi(t)).sqrt() + eps;
        p -= lr / (1.0 - b1.powi(t)) * m / denom;
    }
    p
}

#[test]
fn steps_match_torch_adam() {
    let mut s = model(3);
    let mut adam = Adam::new(&s);
    let seq = [0.3f32, -0.1, 0.05, 0.2, -0.4];
    let lrs = [0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07];
    for &g in &seq {
        let grads = Grads::constant(&s, g);
        adam.step(&mut s, &grads.view(), &lrs, &GroupFlags::ALL_ON, None);
    }
    let gs: Vec<f64> = seq.iter().map(|&g| g as f64).collect();
    let want = |p0: f64, lr: f64| reference(p0, &gs, lr) as f32;
    assert!((s.means[2].x - want(2.0, 0.01)).abs() < 1e-5);
    assert!((s.log_scales[1].y - want(0.0, 0.02)).abs() < 1e-5);
    assert!((s.rotations[0].w - want(1.0, 0.03)).abs() < 1e-5);
    assert!((s.raw_opacities[0] - want(0.0, 0.04)).abs() < 1e-5);
    assert!(
        (s.sh_of(1)[2] - want(0.5, 0.05)).abs() < 1e-5,
        "DC uses the DC rate"
    );
    assert!(
        (s.sh_of(1)[3] - want(0.5, 0.06)).abs() < 1e-5,
        "rest uses the rest rate"
    );
    assert!((s.labels_of(2)[1] - want(0.0, 0.07)).abs() < 1e-5);
    assert_eq!(adam.steps(ParamGroup::Means), 5);
}

#[test]
fn frozen_and_invisible_gaussians_keep_parameters_and_moments() {
    let mut s = model(4);
    s.meta.frozen[1] = true;
    let before = s.clone();
    let mut adam = Adam::new(&s);
    let grads = Grads::constant(&s, 1.0);
    let visible = [true, true, false, true];
    adam.step(
        &mut s,
        &grads.view(),
        &[0.1; 7],
        &GroupFlags::ALL_ON,
        Some(&visible),
    );
    for g in 0..4 {
        let moved = s.means[g] != before.means[g];
        assert_eq!(moved, g == 0 || g == 3, "Gaussian {g}");
        assert_eq!(s.sh_of(g) != before.sh_of(g), moved);
    }
    let (m, v) = adam.moments(ParamGroup::ShRest);
    assert!(
        m[9..18].iter().chain(&v[9..18]).all(|&x| x == 0.0),
        "frozen moments untouched"
    );
    assert!(m[..9].iter().all(|&x| x != 0.0));
}

#[test]
fn disabled_groups_are_not_updated_or_counted() {
    let mut s = model(2);
    let before = s.clone();
    let mut adam = Adam::new(&s);
    let mut flags = GroupFlags::ALL_OFF;
    flags.set(ParamGroup::RawLabels, true);
    let grads = Grads::constant(&s, 1.0);
    adam.step(&mut s, &grads.view(), &[0.1; 7], &flags, None);
    assert_eq!(s.means, before.means);
    assert_eq!(s.sh, before.sh);
    assert_eq!(s.raw_opacities, before.raw_opacities);
    assert_ne!(s.raw_labels, before.raw_labels);
    assert_eq!(adam.steps(ParamGroup::Means), 0);
    assert_eq!(adam.steps(ParamGroup::RawLabels), 1);
}

#[test]
fn append_and_retain_keep_moments_aligned() {
    let mut s = model(3);
    let mut adam = Adam::new(&s);
    let mut grads = Grads::constant(&s, 0.0);
    grads.op = vec![1.0, 2.0, 3.0];
    adam.step(&mut s, &grads.view(), &[0.0; 7], &GroupFlags::ALL_ON, None);
    adam.append(2);
    assert_eq!(adam.len(), 5);
    adam.retain(&[false, true, true, true, false]);
    let (m, _) = adam.moments(ParamGroup::RawOpacities);
    assert_eq!(m.len(), 3);
    assert!((m[0] - 0.2).abs() < 1e-7 && (m[1] - 0.3).abs() < 1e-7 && m[2] == 0.0);
    assert_eq!(adam.moments(ParamGroup::ShRest).0.len(), 3 * 9);
}

#[test]
fn position_rate_scales_with_extent_and_decays() {
    let lr = LearningRates {
        position_max_steps: 1000,
        ..LearningRates::default()
    };
    let a = lr.for_step(0, 5.0);
    let b = lr.for_step(1000, 5.0);
    assert!((a[0] - 1.6e-4 * 5.0).abs() < 1e-9);
    assert!((b[0] - 1.6e-6 * 5.0).abs() < 1e-11);
    assert_eq!(a[ParamGroup::ShRest.index()], 2.5e-3 / 20.0);
}

#[test]
fn a_step_reports_the_first_non_finite_value_it_applied_or_wrote() {
    let clean = Grads::constant(&model(3), 0.5);
    let mut s = model(3);
    let mut adam = Adam::new(&s);
    let step = |s: &mut Splats, adam: &mut Adam, g: &Grads, lrs: [f32; 7]| {
        adam.step(s, &g.view(), &lrs, &GroupFlags::ALL_ON, None)
    };
    assert_eq!(step(&mut s, &mut adam, &clean, [0.1; 7]), None);

    // A NaN gradient of one SH-rest value (the strided path) and one of an opacity (a
    // contiguous group, later in the order than rotations): the earlier group is reported.
    let mut bad = Grads::constant(&s, 0.5);
    bad.sh[12 + 5] = f32::NAN;
    bad.op[2] = f32::INFINITY;
    let found = step(&mut s, &mut adam, &bad, [0.1; 7]);
    assert_eq!(found, Some(NonFinite::Gradient(ParamGroup::RawOpacities)));
    assert!(s.raw_opacities[2].is_nan(), "the damaged value is written");

    // A finite gradient whose update overflows.
    let mut s = model(3);
    let mut adam = Adam::new(&s);
    let mut lrs = [0.1; 7];
    lrs[ParamGroup::LogScales.index()] = f32::MAX;
    let found = step(&mut s, &mut adam, &clean, lrs);
    assert_eq!(found, Some(NonFinite::Parameter(ParamGroup::LogScales)));
    assert_eq!(
        found.map(|f| f.to_string()).as_deref(),
        Some("log_scales became non-finite")
    );

    // Gradients the step does not apply are not looked at: a frozen Gaussian's, an invisible
    // one's, a switched-off group's.
    let mut s = model(3);
    s.meta.frozen[0] = true;
    let mut adam = Adam::new(&s);
    let mut ignored = Grads::constant(&s, 0.5);
    ignored.op[0] = f32::NAN;
    ignored.v3[1] = Vec3::splat(f32::NAN);
    ignored.lb[4] = f32::NAN;
    let visible = [true, false, true];
    let mut flags = GroupFlags::ALL_ON;
    flags.set(ParamGroup::RawLabels, false);
    let found = adam.step(&mut s, &ignored.view(), &[0.1; 7], &flags, Some(&visible));
    assert_eq!(found, None);
    assert!(s.raw_opacities.iter().all(|v| v.is_finite()));
}

#[test]
fn both_sh_groups_in_one_pass_match_one_group_at_a_time() {
    let mut together = model(5);
    together.meta.frozen[1] = true;
    let mut apart = together.clone();
    let mut grads = Grads::constant(&together, 0.0);
    for (i, g) in grads.sh.iter_mut().enumerate() {
        *g = ((i * 37 % 11) as f32 - 5.0) * 1e-2;
    }
    let visible = [true, true, false, true, true];
    let lrs = [0.01, 0.02, 0.03, 0.04, 0.05, 0.006, 0.07];
    let mut sh_only = GroupFlags::ALL_OFF;
    sh_only.set(ParamGroup::ShDc, true);
    sh_only.set(ParamGroup::ShRest, true);
    let mut adam_together = Adam::new(&together);
    let mut adam_apart = Adam::new(&apart);
    for _ in 0..3 {
        let found =
            adam_together.step(&mut together, &grads.view(), &lrs, &sh_only, Some(&visible));
        assert_eq!(found, None);
        for group in [ParamGroup::ShDc, ParamGroup::ShRest] {
            let mut one = GroupFlags::ALL_OFF;
            one.set(group, true);
            let found = adam_apart.step(&mut apart, &grads.view(), &lrs, &one, Some(&visible));
            assert_eq!(found, None);
        }
    }
    assert_eq!(together.sh, apart.sh);
    assert_eq!(adam_together, adam_apart);
    assert_ne!(together.sh, model(5).sh);
    // The frozen and the invisible Gaussian kept their coefficients.
    let k3 = together.sh_coeffs() * 3;
    assert_eq!(together.sh[k3..3 * k3], model(5).sh[k3..3 * k3]);
}

#[test]
fn per_gaussian_rates_scale_each_gaussians_steps() {
    let mut s = model(3);
    let mut adam = Adam::new(&s);
    adam.set_rates(ParamGroup::Means, Some(vec![1.0, 0.1, 0.0]))
        .expect("three factors");
    adam.set_rates(ParamGroup::RawOpacities, Some(vec![0.5, 1.0, 1.0]))
        .expect("three factors");
    assert!(adam.set_rates(ParamGroup::Means, Some(vec![1.0])).is_err());
    assert!(
        adam.set_rates(ParamGroup::ShDc, Some(vec![1.0; 3]))
            .is_err()
    );
    let grads = Grads::constant(&s, 0.3);
    let seq = [0.3f64; 4];
    for _ in 0..4 {
        adam.step(&mut s, &grads.view(), &[0.1; 7], &GroupFlags::ALL_ON, None);
    }
    // Each Gaussian follows torch's Adam at its own rate; groups without factors are unscaled.
    let want = |p0: f64, lr: f64| reference(p0, &seq, lr) as f32;
    assert!((s.means[0].x - want(0.0, 0.1)).abs() < 1e-5);
    assert!((s.means[1].x - want(1.0, 0.01)).abs() < 1e-5);
    assert_eq!(s.means[2], Vec3::splat(2.0), "factor 0: the Gaussian stays");
    assert!((s.raw_opacities[0] - want(0.0, 0.05)).abs() < 1e-5);
    assert!((s.raw_opacities[1] - want(0.0, 0.1)).abs() < 1e-5);
    assert!((s.log_scales[1].x - want(0.0, 0.1)).abs() < 1e-5);
    // Pruning keeps each survivor's factor; appended Gaussians get 1.
    adam.retain(&[false, true, true]);
    s.retain(&[false, true, true]);
    adam.append(1);
    s.push(
        Vec3::ZERO,
        Vec3::ZERO,
        Quat::IDENTITY,
        0.0,
        &[0.5; 12],
        &[0.0; 2],
        9,
        0,
    );
    let before: Vec<Vec3> = s.means.clone();
    let grads = Grads::constant(&s, 0.3);
    adam.step(&mut s, &grads.view(), &[0.1; 7], &GroupFlags::ALL_ON, None);
    assert_eq!(s.means[1], before[1], "the factor-0 Gaussian still stays");
    // The new Gaussian's first moments, bias-corrected with the group's fifth step, at rate 1.
    let (m, v) = (0.1f64 * 0.3, 0.001f64 * 0.09);
    let full = 0.1 / (1.0 - 0.9f64.powi(5)) * m / (v.sqrt() / (1.0 - 0.999f64.powi(5)).sqrt());
    assert!(
        (s.means[2].x as f64 + full).abs() < 1e-5,
        "{}",
        s.means[2].x
    );
}

/// Seeded gradients in every group (a NaN in the frozen Gaussian `nan_at`, which no step may
/// read).
fn seeded_grads(s: &Splats, seed: u64, nan_at: usize) -> Grads {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut value = || rng.f32() - 0.5;
    let mut grads = Grads {
        v3: (0..s.len())
            .map(|_| Vec3::new(value(), value(), value()))
            .collect(),
        v4: (0..s.len())
            .map(|_| Vec4::new(value(), value(), value(), value()))
            .collect(),
        op: (0..s.len()).map(|_| value()).collect(),
        sh: (0..s.sh.len()).map(|_| value()).collect(),
        lb: (0..s.raw_labels.len()).map(|_| value()).collect(),
    };
    grads.op[nan_at] = f32::NAN;
    grads.sh[nan_at * s.sh_coeffs() * 3 + 5] = f32::NAN;
    grads
}

fn bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|x| x.to_bits()).collect()
}

/// Moments for the trainable Gaussians only (`for_trainable`) step, grow, shrink and reset as
/// moments for every Gaussian (`new`) do: the same parameters and reports bit for bit, the same
/// moments where kept and zeros elsewhere. Several tasks' worth of listed Gaussians, so the list
/// is split; every update path (contiguous groups gathered, per-Gaussian rates, the fused and
/// the separate SH groups) runs.
#[test]
fn moments_for_the_trainable_only_match_moments_for_every_gaussian() {
    let n = 8 * GAUSSIANS_PER_TASK + 77;
    let mut dense_s = model(n);
    let mut rng = fastrand::Rng::with_seed(5);
    for g in 0..n {
        // Runs of frozen Gaussians and scattered ones.
        dense_s.meta.frozen[g] = (g / 37) % 3 != 0 || rng.f32() < 0.1;
    }
    let mut listed_s = dense_s.clone();
    let mut dense = Adam::new(&dense_s);
    let mut listed = Adam::for_trainable(&listed_s);
    let tracked = listed
        .listed()
        .expect("only the trainable have moments")
        .len();
    assert!(tracked > GAUSSIANS_PER_TASK && tracked < n / 2, "{tracked}");
    let rates: Vec<f32> = (0..n).map(|_| 0.5 + rng.f32()).collect();
    for adam in [&mut dense, &mut listed] {
        adam.set_rates(ParamGroup::LogScales, Some(rates.clone()))
            .unwrap();
    }
    let lrs = [0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07];
    for step in 0..12u64 {
        let first_frozen = dense_s.meta.frozen.iter().position(|&f| f).unwrap();
        let mut grads = seeded_grads(&dense_s, step, first_frozen);
        let visible: Vec<bool> = (0..dense_s.len()).map(|_| rng.f32() < 0.8).collect();
        let mut flags = GroupFlags::ALL_ON;
        flags.set(ParamGroup::ShRest, step % 3 != 2);
        flags.set(ParamGroup::Means, step % 4 != 3);
        if step == 11 {
            let trainable_visible = (0..dense_s.len())
                .find(|&g| !dense_s.meta.frozen[g] && visible[g])
                .unwrap();
            grads.lb[trainable_visible * 2] = f32::INFINITY;
        }
        let a = dense.step(&mut dense_s, &grads.view(), &lrs, &flags, Some(&visible));
        let b = listed.step(&mut listed_s, &grads.view(), &lrs, &flags, Some(&visible));
        assert_eq!(a, b, "step {step}: reports");
        assert_eq!(a.is_some(), step == 11, "step {step}: {a:?}");
        match step {
            // Densification's children, trainable, at the end.
            4 => {
                for s in [&mut dense_s, &mut listed_s] {
                    for g in [3usize, 40, 41, 2000] {
                        let (sh, labels) = (s.sh_of(g).to_vec(), s.labels_of(g).to_vec());
                        let (mean, ls) = (s.means[g] + Vec3::X, s.log_scales[g]);
                        let (rot, op) = (s.rotations[g], s.raw_opacities[g]);
                        s.push(mean, ls, rot, op, &sh, &labels, (n + g) as u64, 0);
                    }
                }
                dense.append(4);
                listed.append(4);
            }
            // A prune of frozen and trainable Gaussians.
            7 => {
                let keep: Vec<bool> = (0..dense_s.len()).map(|_| rng.f32() < 0.9).collect();
                for (s, adam) in [(&mut dense_s, &mut dense), (&mut listed_s, &mut listed)] {
                    s.retain(&keep);
                    adam.retain(&keep);
                }
            }
            // An opacity reset's zeroing, frozen Gaussians included.
            9 => {
                for g in (0..dense_s.len()).step_by(7) {
                    dense.reset_gaussian(ParamGroup::RawOpacities, g);
                    listed.reset_gaussian(ParamGroup::RawOpacities, g);
                }
            }
            _ => {}
        }
        for (p, q) in [
            (&dense_s.sh, &listed_s.sh),
            (&dense_s.raw_opacities, &listed_s.raw_opacities),
            (&dense_s.raw_labels, &listed_s.raw_labels),
        ] {
            assert_eq!(bits(p), bits(q), "step {step}: parameters");
        }
        for (p, q) in [
            (&dense_s.means, &listed_s.means),
            (&dense_s.log_scales, &listed_s.log_scales),
        ] {
            let (p, q): (&[f32], &[f32]) = (bytemuck::cast_slice(p), bytemuck::cast_slice(q));
            assert_eq!(bits(p), bits(q), "step {step}: geometry");
        }
        let (p, q): (&[f32], &[f32]) = (
            bytemuck::cast_slice(&dense_s.rotations),
            bytemuck::cast_slice(&listed_s.rotations),
        );
        assert_eq!(bits(p), bits(q), "step {step}: rotations");
        let every = listed.with_every_gaussian();
        for group in ParamGroup::ALL {
            let ((m, v), (em, ev)) = (dense.moments(group), every.moments(group));
            assert_eq!(bits(m), bits(em), "step {step}: {} m", group.name());
            assert_eq!(bits(v), bits(ev), "step {step}: {} v", group.name());
            assert_eq!(dense.steps(group), listed.steps(group));
        }
        assert_eq!(dense.len(), listed.len());
    }
    // Nothing frozen: moments for every Gaussian, without a list.
    assert!(Adam::for_trainable(&model(3)).listed().is_none());
}
