//! Live training as the viewer drives it: a tiny demo building opened and trained through
//! commands, with pause / resume / stop, while the state is only ever polled (never waits).
#![cfg(feature = "app")]

use std::time::{Duration, Instant};

use damage_twin::app::commands::Command;
use damage_twin::app::settings::{Settings, TrainMode, TrainingSettings};
use damage_twin::app::state::AppState;
use damage_twin::app::training::RunStatus;

fn poll_until(state: &mut AppState, what: &str, limit: Duration, done: impl Fn(&AppState) -> bool) {
    let start = Instant::now();
    while !done(state) {
        let before = Instant::now();
        state.poll();
        // The UI thread's share of the work: polling must stay far below a frame.
        assert!(before.elapsed() < Duration::from_millis(50), "poll blocked");
        assert!(
            start.elapsed() < limit,
            "timed out waiting for {what}; log: {:?}",
            state.log
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn status(state: &AppState) -> Option<RunStatus> {
    state.training.as_ref().map(|t| t.status.clone())
}

#[test]
fn the_viewer_trains_a_small_building_live_and_obeys_pause_and_stop() {
    let dir = tempfile::tempdir().expect("temp dir");
    // 8 views at 96×64: the smallest building that still trains meaningfully in seconds.
    let data = damage_twin::synth::demo::ensure(&dir.path().join("demo"), 8, 96, 64, &|_, _| {})
        .expect("synth generates the demo");

    let settings = Settings {
        training: TrainingSettings {
            iterations: 60,
            scale: damage_twin::scene::ImageScale::Factor(1),
            mode: TrainMode::Label,
            label_weight: 0.1,
            budget: None,
        },
        ..Settings::default()
    };
    let mut state = AppState::new(settings);
    state.train_on_open = true;
    state.apply(Command::Open(data));
    poll_until(
        &mut state,
        "the first progress",
        Duration::from_secs(30),
        |s| s.training.as_ref().is_some_and(|t| t.progress.is_some()),
    );

    state.apply(Command::PauseTraining);
    assert_eq!(status(&state), Some(RunStatus::Paused));
    // Drain what was in flight, then the step count must stand still.
    std::thread::sleep(Duration::from_millis(300));
    state.poll();
    let paused_at = state.history.last().map(|s| s.step);
    std::thread::sleep(Duration::from_millis(300));
    state.poll();
    assert_eq!(
        state.history.last().map(|s| s.step),
        paused_at,
        "no steps while paused"
    );

    state.apply(Command::ResumeTraining);
    poll_until(
        &mut state,
        "the run to finish",
        Duration::from_secs(60),
        |s| matches!(status(s), Some(RunStatus::Finished { .. })),
    );
    let Some(RunStatus::Finished { cancelled, .. }) = status(&state) else {
        unreachable!()
    };
    assert!(!cancelled);
    assert_eq!(state.history.last().map(|s| s.step), Some(60));
    let splats = state.splats.as_ref().expect("the final model is on screen");
    assert!(!splats.is_empty());
    assert_eq!(
        splats.label_channels, 3,
        "label mode trains one channel per class"
    );
    assert!(
        !state.history.evals.is_empty(),
        "held-out PSNR reported for the chart"
    );

    // A second run can be stopped early; the final snapshot still arrives.
    state.apply(Command::StartTraining);
    poll_until(
        &mut state,
        "the second run to start",
        Duration::from_secs(30),
        |s| s.training.as_ref().is_some_and(|t| t.progress.is_some()),
    );
    state.apply(Command::StopTraining);
    poll_until(&mut state, "the stop", Duration::from_secs(30), |s| {
        matches!(status(s), Some(RunStatus::Finished { .. }))
    });
    assert!(matches!(
        status(&state),
        Some(RunStatus::Finished {
            cancelled: true,
            ..
        })
    ));
}
