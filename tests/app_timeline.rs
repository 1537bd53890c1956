//! The timeline in the viewer (issue 22), driven headless through commands as the timeline strip
//! drives it: a two-survey project opens on the survey that has a model, steps to the later
//! survey, detects its changes (change maps shown when snapping), updates the twin (the later
//! survey's model is written, the earlier one's file is untouched), compares the two surveys,
//! and the selection, hand edits and the shown survey survive save and reopen.
#![cfg(feature = "app")]

mod twin_support;

use std::time::{Duration, Instant};

use damage_twin::app::commands::Command;
use damage_twin::app::settings::Settings;
use damage_twin::app::state::{AppState, Photo};
use damage_twin::damage::DamageClass;
use damage_twin::damage::layer::EARLIER_DAMAGE;
use damage_twin::damage::refine::Strategy;
use damage_twin::splats::model::state::SELECTED;
use damage_twin::splats::selection::{SetOp, selected_count};
use damage_twin::timeline::Twin;
use damage_twin::timeline::survey::AlignMode;

/// Polls until `done` holds (workers report asynchronously), at most `seconds`.
fn poll_until(state: &mut AppState, seconds: u64, done: impl Fn(&AppState) -> bool) {
    let start = Instant::now();
    while !done(state) {
        state.poll();
        assert!(
            start.elapsed() < Duration::from_secs(seconds),
            "timed out; log: {:?}",
            state.log
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn current(state: &AppState) -> Option<usize> {
    state.timeline.as_ref().map(|t| t.current)
}

#[test]
fn stepping_detecting_updating_comparing_and_reopening_a_two_survey_project() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, coarse) = twin_support::coarse_twin(dir.path(), 2);
    let project = dir.path().join("project");
    let mut twin = Twin::create(&project).expect("creates the project");
    twin.add_survey("2024", "2024-06-01", &dir.path().join("synth/survey-1"))
        .expect("adds survey 1");
    let first_model = twin.save_model("2024", &coarse).expect("saves survey 1");
    twin.add_placed_survey(
        "2025",
        "2025-06-01",
        &dir.path().join("synth/survey-2"),
        AlignMode::SameFrame,
    )
    .expect("places survey 2");
    twin.save().expect("saves the project");
    let first_bytes = std::fs::read(&first_model).expect("reads survey 1's model");

    // Opens on the latest survey with a model: 2024 (2025 has none yet).
    let mut state = AppState::new(Settings::default());
    state.apply(Command::Open(project.clone()));
    poll_until(&mut state, 30, |s| s.timeline.is_some());
    assert_eq!(current(&state), Some(0));
    assert_eq!(state.splats.as_ref().map(|s| s.len()), Some(coarse.len()));
    let views_2024 = state.survey_cameras().len();

    // Step to 2025: its photos (8 views), no model yet; the camera stays where it was.
    let camera_before = state.view_camera(64, 48);
    state.apply(Command::ShowSurvey(1));
    poll_until(&mut state, 30, |s| current(s) == Some(1));
    assert_eq!(state.survey_cameras().len(), 8);
    assert_ne!(views_2024, 8);
    assert!(state.splats.is_none(), "2025 has no model yet");
    assert_eq!(state.view_camera(64, 48), camera_before);

    // Detect changes: change maps written and recorded; snapping shows one instead of the photo.
    state.apply(Command::DetectChanges);
    assert!(state.timeline.as_ref().is_some_and(|t| t.job.is_some()));
    poll_until(&mut state, 120, |s| {
        s.timeline.as_ref().is_some_and(|t| t.job.is_none())
    });
    let timeline = state.timeline.as_ref().expect("timeline");
    let changes = timeline.twin.project.surveys[1]
        .changes
        .clone()
        .unwrap_or_else(|| panic!("changes recorded; log: {:?}", state.log));
    let folder = timeline.twin.resolve(&changes);
    assert!(folder.join("changes.json").is_file());
    assert!(
        timeline.show_change_maps,
        "the change maps are shown after detection"
    );
    state.apply(Command::SnapToView(0));
    let snap = state.snap.as_ref().expect("snapped");
    assert!(snap.change_map, "the snapped view shows its change map");
    poll_until(&mut state, 10, |s| {
        s.snap
            .as_ref()
            .is_some_and(|s| matches!(s.photo, Photo::Loaded(_)))
    });
    state.apply(Command::ShowChangeMaps(false));
    assert!(state.snap.as_ref().is_some_and(|s| !s.change_map));
    state.apply(Command::Unsnap);

    // Update the twin with 2025: its model is written, 2024's file is byte for byte the same.
    state.apply(Command::UpdateTwin {
        strategy: Strategy::Finetune,
        iterations: 20,
    });
    poll_until(&mut state, 600, |s| {
        s.timeline.as_ref().is_some_and(|t| t.job.is_none())
    });
    let timeline = state.timeline.as_ref().expect("timeline");
    assert!(
        timeline.twin.project.surveys[1].model.is_some(),
        "2025 has a model; log: {:?}",
        state.log
    );
    let updated = timeline
        .twin
        .load_model("2025")
        .expect("loads 2025")
        .expect("2025 has a model");
    assert!(
        updated.len() >= coarse.len(),
        "fine-tune keeps survey 1's Gaussians and adds the new-damage seeds"
    );
    assert_eq!(
        state.splats.as_ref().map(|s| s.len()),
        Some(updated.len()),
        "the updated model is shown"
    );
    assert_eq!(std::fs::read(&first_model).expect("reads"), first_bytes);
    // The update's progress is kept for the report's training chart: 20 steps of loss, and the
    // held-out PSNR before and after.
    let history = timeline
        .twin
        .load_history("2025")
        .expect("reads the history")
        .expect("the update kept its history");
    assert!(history.series(|s| s.loss).len() >= 20, "{history:?}");
    assert_eq!(history.evals.len(), 2, "{:?}", history.evals);

    // Compare with 2024: its model loads beside; the layers colour by the later survey.
    state.apply(Command::CompareSurvey(Some(0)));
    poll_until(&mut state, 30, |s| {
        s.timeline.as_ref().is_some_and(|t| t.compared().is_some())
    });
    let timeline = state.timeline.as_ref().expect("timeline");
    let (index, compared) = timeline.compared().expect("compared");
    assert_eq!(index, 0);
    assert_eq!(compared.means, coarse.means);
    let new_colour = timeline.twin.project.settings.new_damage_colour;
    for survey in [0, 1] {
        let layer = timeline.layer(&state.settings.damage, survey);
        assert_eq!(layer.survey_colours, vec![EARLIER_DAMAGE, new_colour]);
        assert_eq!(usize::from(layer.own_survey), survey);
    }
    // Stepping to the compared survey swaps the two.
    state.apply(Command::ShowSurvey(0));
    assert_eq!(current(&state), Some(0));
    assert_eq!(state.timeline.as_ref().and_then(|t| t.compare), Some(1));
    state.apply(Command::ShowSurvey(1));
    assert_eq!(current(&state), Some(1));

    // A hand edit on 2025 (crack marked on the selection), saved and reopened.
    state.apply(Command::SelectDamage {
        class: DamageClass::Spalling,
        threshold: 0.5,
        survey: None,
        op: SetOp::Set,
    });
    let selected = state
        .splats
        .as_ref()
        .map(|s| selected_count(s))
        .unwrap_or(0);
    assert!(selected > 0, "the updated twin has spalling Gaussians");
    state.apply(Command::SetDamageClass {
        class: DamageClass::Crack,
        on: true,
    });
    let edited = state.splats.clone().expect("model");
    state.apply(Command::SaveProjectHere);
    assert!(
        state.log.iter().any(|l| l.starts_with("saved the twin")),
        "{:?}",
        state.log
    );
    assert_eq!(std::fs::read(&first_model).expect("reads"), first_bytes);

    let mut reopened = AppState::new(Settings::default());
    reopened.apply(Command::Open(project.clone()));
    poll_until(&mut reopened, 30, |s| s.timeline.is_some());
    assert_eq!(current(&reopened), Some(1), "the shown survey survives");
    let model = reopened.splats.clone().expect("model");
    assert_eq!(selected_count(&model), selected, "the selection survives");
    for g in 0..model.len() {
        assert_eq!(
            model.meta.state[g] & SELECTED,
            edited.meta.state[g] & SELECTED
        );
    }
    let crack = DamageClass::Crack.channel();
    let channels = model.label_channels;
    for g in 0..model.len() {
        assert_eq!(
            model.raw_labels[g * channels + crack],
            edited.raw_labels[g * channels + crack],
            "the hand-set crack label of Gaussian {g} survives"
        );
    }
}
