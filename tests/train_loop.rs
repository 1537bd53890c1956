//! The training loop end to end on a tiny synthetic scene: PSNR rises, a seed fixes the run,
//! NaN steps are rolled back, and the job obeys pause / resume / cancel.

mod blob_scene;

use std::time::{Duration, Instant};

use glam::Vec3;

use blob_scene::{initial, scene};
use damage_twin::splats::Splats;
use damage_twin::train::evaluate::evaluate_views;
use damage_twin::train::job::{JobEvent, JobOptions};
use damage_twin::train::run::{self as run, TrainOutcome, TrainSetup};
use damage_twin::train::spec::{TrainSpec, TrainView};
use damage_twin::train::trainer::Trainer;

fn spec(iterations: u32, seed: u64) -> TrainSpec {
    let mut spec = TrainSpec::reconstruction(iterations);
    spec.sh_degree = 1;
    spec.seed = seed;
    spec
}

fn train(iterations: u32, seed: u64, views: &[TrainView]) -> Splats {
    let mut trainer = Trainer::new(spec(iterations, seed), initial(), views.to_vec()).unwrap();
    while !trainer.is_done() {
        let report = trainer.step();
        assert!(report.rolled_back.is_none(), "{report:?}");
    }
    trainer.into_splats()
}

#[test]
fn training_raises_heldout_psnr_and_a_seed_fixes_the_run() {
    let (views, heldout) = scene();
    let before = evaluate_views(&initial(), &heldout, Vec3::ZERO, 1)
        .unwrap()
        .psnr;
    let a = train(400, 11, &views);
    let after = evaluate_views(&a, &heldout, Vec3::ZERO, 1).unwrap().psnr;
    // Measured: about 11 dB before, 24 dB after 400 steps; 8 dB of gain leaves room for noise.
    assert!(
        after > before + 8.0,
        "held-out PSNR {before:.2} -> {after:.2} dB"
    );

    let b = train(400, 11, &views);
    assert!(
        a == b,
        "same seed and thread count must give the same model"
    );
    let c = train(400, 12, &views);
    assert!(a != c, "another seed must give another view order");
}

#[test]
fn a_nan_step_is_rolled_back_and_training_recovers() {
    let (views, heldout) = scene();
    let mut trainer = Trainer::new(spec(200, 1), initial(), views).unwrap();
    for _ in 0..50 {
        assert!(trainer.step().rolled_back.is_none());
    }
    let good = trainer.splats().clone();
    // Every Gaussian's colour: whichever view comes next sees NaN.
    for g in 0..trainer.splats().len() {
        trainer.poison_for_test(g);
    }
    // Projection culls a Gaussian with a non-finite parameter (as the GPU does), so the poisoned
    // model renders nothing rather than NaN, and visible Adam leaves it alone. The full scan
    // before the next checkpoint must find it: here the opacity reset at step 66, the first
    // density change (checkpoints come every 100 steps and after density changes).
    let report = loop {
        let report = trainer.step();
        if report.rolled_back.is_some() || report.step >= 100 {
            break report;
        }
    };
    let reason = report.rolled_back.expect("the NaN must be reported");
    assert!(reason.contains("non-finite"), "{reason}");
    assert!(reason.contains("restored to step"), "{reason}");
    assert_eq!(report.step, 66);
    // Restored to the last checkpoint: step 0 here.
    assert_ne!(trainer.splats(), &good);
    assert_eq!(
        trainer.splats(),
        &initial(),
        "restored to the step-0 checkpoint"
    );
    while !trainer.is_done() {
        assert!(trainer.step().rolled_back.is_none());
    }
    let psnr = trainer.evaluate(&heldout).psnr;
    assert!(psnr.is_finite() && psnr > 15.0, "{psnr}");
}

#[test]
fn a_nan_target_pixel_is_reported_as_an_event_and_skipped() {
    let (mut views, heldout) = scene();
    views[3].image.data[100] = f32::NAN;
    let job = run::train(
        TrainSetup {
            spec: spec(60, 2),
            splats: initial(),
            views,
            heldout,
        },
        JobOptions::default(),
    );
    let mut rolled = Vec::new();
    let mut finished = None;
    for event in job.events().iter() {
        match event {
            JobEvent::NanRolledBack { step, reason } => rolled.push((step, reason)),
            JobEvent::Finished(o) => finished = Some(o),
            JobEvent::Failed(e) => panic!("{e}"),
            _ => {}
        }
    }
    let outcome = finished.expect("finished");
    // 60 steps over 12 views: view 3 comes up 5 times, each one skipped.
    assert_eq!(rolled.len(), 5, "{rolled:?}");
    assert!(
        rolled
            .iter()
            .all(|(_, r)| r.contains("loss") && r.contains("skipped"))
    );
    assert_eq!(outcome.rolled_back, 5);
    assert_eq!(outcome.steps, 60);
    assert!(outcome.splats.sh.iter().all(|v| v.is_finite()));
}

#[test]
fn job_pauses_resumes_and_cancels() {
    let (views, heldout) = scene();
    let job = run::train(
        TrainSetup {
            spec: spec(1_000_000, 3),
            splats: initial(),
            views,
            heldout,
        },
        JobOptions {
            threads: Some(1),
            snapshot_interval: Some(Duration::from_millis(50)),
            // As the viewer runs it: worker and pool threads at a lower priority.
            low_priority: true,
        },
    );
    let events = job.events().clone();
    let step_of = |e: &JobEvent<TrainOutcome>| match e {
        JobEvent::Progress(p) => Some(p.step),
        _ => None,
    };
    // Wait for some progress and a snapshot.
    let mut last = 0;
    let mut snapshots = 0;
    while last < 20 {
        let e = events
            .recv_timeout(Duration::from_secs(20))
            .expect("progress");
        if matches!(e, JobEvent::Snapshot(_)) {
            snapshots += 1;
        }
        last = step_of(&e).unwrap_or(last);
    }
    assert!(snapshots >= 1);
    job.pause();
    // Drain what was in flight, then nothing may arrive while paused.
    std::thread::sleep(Duration::from_millis(100));
    while let Ok(e) = events.try_recv() {
        last = step_of(&e).unwrap_or(last);
    }
    let quiet = Instant::now();
    assert!(
        events.recv_timeout(Duration::from_millis(300)).is_err(),
        "paused job sent events"
    );
    assert!(quiet.elapsed() >= Duration::from_millis(290));
    job.resume();
    let e = events
        .recv_timeout(Duration::from_secs(20))
        .expect("resumed");
    if let Some(step) = step_of(&e) {
        assert_eq!(step, last + 1, "resumed where it paused");
    }
    job.cancel();
    let outcome = job.wait().expect("cancelled jobs finish");
    assert!(outcome.cancelled);
    assert!(outcome.steps > last && outcome.steps < 1_000_000);
    assert!(outcome.heldout.is_some());
}
