//! The viewer watches its open project for other writers (issue 45 §1): another process holding
//! the project's lock is named in the timeline strip, and a `twin.ron` another process changed is
//! read again, so the viewer never shows a stale record as current. Quick: no training.
#![cfg(feature = "app")]

mod app_support;
mod project_support;

use std::time::{Duration, Instant};

use app_support::viewer_on_one_survey;
use damage_twin::app::state::AppState;
use damage_twin::timeline::Twin;
use damage_twin::timeline::lock::LOCK_FILE;

/// Polls until `done` holds, at most 10 s (the watch looks once a second).
fn poll_until(state: &mut AppState, done: impl Fn(&AppState) -> bool) {
    let start = Instant::now();
    while !done(state) {
        state.poll();
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "timed out; log: {:?}",
            state.log
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn holder(state: &AppState) -> Option<String> {
    let timeline = state.timeline.as_ref()?;
    timeline.watch.holder.as_ref().map(|h| h.to_string())
}

#[test]
fn another_writer_is_named_and_its_change_read_again() {
    let dir = tempfile::tempdir().expect("temp dir");
    let project = dir.path().join("project");
    let mut state = viewer_on_one_survey(&project, "2024", &dir.path().join("data/2024"));

    // Another process adds a survey: the viewer reads the record again.
    let mut other = Twin::open(&project).expect("opens");
    other
        .add_survey("2025", "2025-06-01", &dir.path().join("data/2025"))
        .expect("adds a second survey");
    other.save().expect("saves");
    poll_until(&mut state, |s| {
        s.timeline
            .as_ref()
            .is_some_and(|t| t.twin.project.surveys.len() == 2)
    });
    assert!(
        state.log.iter().any(|l| l.contains("changed on disk")),
        "{:?}",
        state.log
    );
    assert_eq!(state.timeline.as_ref().map(|t| t.current), Some(0));

    // Another process holds the lock (process 1 is always alive): named while it does.
    let lock = project.join(LOCK_FILE);
    std::fs::write(&lock, "command: twin update\npid: 1\nsince: 0\n").expect("writes");
    poll_until(&mut state, |s| holder(s).is_some());
    assert_eq!(
        holder(&state).as_deref(),
        Some("`twin update` (pid 1) since 1970-01-01 00:00 UTC")
    );
    // Let go (a holder empties the file): no longer named.
    std::fs::write(&lock, "").expect("empties");
    poll_until(&mut state, |s| holder(s).is_none());
}
