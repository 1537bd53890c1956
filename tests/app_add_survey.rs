//! "Add survey…" in the viewer (issue 41 §2), driven headless through the commands its dialog
//! queues: a later survey's folder chosen (as the file dialog returns it) and added on a worker
//! through `timeline::add_survey`'s job, then in the timeline strip and in `twin.ron`; a folder
//! that is not a dataset refused in the dialog with the project unchanged; a survey segmented
//! with the shared crack model first, and the same add cancelled half-way leaving no survey and
//! no masks. Quick: no training, 192×108 photos.
#![cfg(feature = "app")]

mod app_support;
mod project_support;
mod shared_data;

use std::path::Path;
use std::time::{Duration, Instant};

use app_support::viewer_on_one_survey;
use damage_twin::app::commands::Command;
use damage_twin::app::state::AppState;
use damage_twin::app::survey_form::AddSurveyForm;
use damage_twin::scene::DamageClass;
use damage_twin::scene::masks::count_masks;
use damage_twin::scene::project::PROJECT_FILE;
use damage_twin::timeline::Twin;

/// Polls until no timeline job runs, at most 60 s.
fn poll_until_idle(state: &mut AppState) {
    let start = Instant::now();
    loop {
        state.poll();
        if state.timeline.as_ref().is_some_and(|t| t.job.is_none()) {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "timed out; log: {:?}",
            state.log
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A two-survey synthetic building in `dir/synth` (survey 2's masks removed: photos alone) and
/// a project in `dir/project` holding survey 1 with a one-Gaussian model, open in a viewer.
fn viewer_on_project(dir: &Path) -> AppState {
    let params = damage_twin::synth::SynthParams {
        width: 192,
        height: 108,
        views: 4,
        views_survey2: 3,
        surveys: 2,
        sparse_points: 500,
        ..damage_twin::synth::SynthParams::demo(dir.join("synth"))
    };
    damage_twin::synth::generate(&params, &|_, _| {}).expect("synth");
    std::fs::remove_dir_all(dir.join("synth/survey-2/masks")).expect("removes the masks");
    viewer_on_one_survey(
        &dir.join("project"),
        "survey-1",
        &dir.join("synth/survey-1"),
    )
}

fn form(state: &AppState) -> &AddSurveyForm {
    state.add_survey.as_ref().expect("the dialog is open")
}

fn surveys(state: &AppState) -> Vec<String> {
    let timeline = state.timeline.as_ref().expect("timeline");
    timeline
        .twin
        .project
        .surveys
        .iter()
        .map(|s| s.name.clone())
        .collect()
}

/// The dialog's fields edited as the panel edits them.
fn edit(state: &mut AppState, change: impl FnOnce(&mut AddSurveyForm)) {
    let mut edited = form(state).clone();
    change(&mut edited);
    state.apply(Command::EditAddSurvey(Box::new(edited)));
}

#[test]
fn a_chosen_folder_is_added_and_shown_in_the_timeline_and_a_bad_folder_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut state = viewer_on_project(dir.path());
    let project_file = dir.path().join("project").join(PROJECT_FILE);
    let saved = std::fs::read(&project_file).expect("twin.ron");

    state.apply(Command::OpenAddSurvey);
    assert!(form(&state).date.as_str() >= "2024-06-01", "dated today");
    // Nothing chosen yet: the dialog says so, no job starts.
    state.apply(Command::AddSurvey);
    assert!(state.timeline.as_ref().is_some_and(|t| t.job.is_none()));
    let problem = form(&state).error.clone().unwrap_or_default();
    assert!(problem.contains("dataset folder"), "{problem}");

    // A folder that does not exist, then one that is no dataset: refused in the dialog, naming
    // it; the project on disk and in the viewer as it was.
    for bad in [dir.path().join("nothing-here"), dir.path().join("project")] {
        state.apply(Command::ChooseSurveyDataset(bad.clone()));
        edit(&mut state, |f| f.name = "later".into());
        state.apply(Command::AddSurvey);
        poll_until_idle(&mut state);
        let problem = form(&state).error.clone().unwrap_or_default();
        assert!(
            problem.contains(&bad.display().to_string()),
            "{bad:?}: {problem}"
        );
        assert_eq!(surveys(&state), ["survey-1"]);
        assert_eq!(std::fs::read(&project_file).expect("twin.ron"), saved);
    }

    // The survey's folder as the file dialog returns it: its name fills the survey name.
    edit(&mut state, |f| f.name.clear());
    let second = dir.path().join("synth/survey-2");
    state.apply(Command::ChooseSurveyDataset(second.clone()));
    assert_eq!(form(&state).name, "survey-2");
    assert_eq!(form(&state).dataset, second.display().to_string());
    state.apply(Command::AddSurvey);
    assert!(
        state.timeline.as_ref().is_some_and(|t| t.job.is_some()),
        "added on a worker; log: {:?}",
        state.log
    );
    poll_until_idle(&mut state);
    assert!(state.add_survey.is_none(), "closed; log: {:?}", state.log);
    assert_eq!(surveys(&state), ["survey-1", "survey-2"]);
    let on_disk = Twin::open(&dir.path().join("project")).expect("opens");
    assert_eq!(on_disk.project.surveys.len(), 2);
    assert!(
        state
            .log
            .iter()
            .any(|l| l == "added survey survey-2 (same frame)")
    );

    // The strip steps to it: its three photos in the twin's frame.
    state.apply(Command::ShowSurvey(1));
    let start = Instant::now();
    while state.timeline.as_ref().is_some_and(|t| t.current != 1) {
        state.poll();
        assert!(start.elapsed() < Duration::from_secs(30), "{:?}", state.log);
        std::thread::sleep(Duration::from_millis(10));
    }
    let shown = state.timeline.as_ref().and_then(|t| t.loaded.get(&1));
    let views = shown
        .and_then(|s| s.dataset.as_ref())
        .map(|d| d.views.len());
    assert_eq!(views, Some(3), "{:?}", state.log);
}

#[test]
fn segment_with_the_crack_model_then_add_and_a_cancel_leaves_nothing() {
    let Some(model) = shared_data::path("crack_unet_crackpot/crack_unet.onnx") else {
        return;
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let mut state = viewer_on_project(dir.path());
    let second = dir.path().join("synth/survey-2");
    let project_file = dir.path().join("project").join(PROJECT_FILE);
    let saved = std::fs::read(&project_file).expect("twin.ron");
    state.apply(Command::OpenAddSurvey);
    state.apply(Command::ChooseSurveyDataset(second.clone()));
    state.apply(Command::ChooseSegmentModel(model.clone()));
    edit(&mut state, |f| f.segment = true);
    assert_eq!(form(&state).model, model.display().to_string());

    // Cancelled at once (the model takes a while to read): no survey, no mask left behind, and
    // the dialog says so.
    state.apply(Command::AddSurvey);
    state.apply(Command::CancelTimelineJob);
    poll_until_idle(&mut state);
    let problem = form(&state).error.clone().unwrap_or_default();
    assert!(problem.contains("cancelled"), "{problem}; {:?}", state.log);
    assert_eq!(surveys(&state), ["survey-1"]);
    assert_eq!(std::fs::read(&project_file).expect("twin.ron"), saved);
    assert!(!second.join("masks").exists(), "the cancelled run's masks");
    assert!(!second.join("probabilities").exists());

    // Again, to the end: masks written into the dataset, then the survey added.
    state.apply(Command::AddSurvey);
    poll_until_idle(&mut state);
    assert!(state.add_survey.is_none(), "log: {:?}", state.log);
    assert_eq!(surveys(&state), ["survey-1", "survey-2"]);
    assert_eq!(
        count_masks(&second.join("masks")).get(&DamageClass::Crack),
        Some(&3)
    );
    assert!(
        state
            .log
            .iter()
            .any(|l| l.starts_with("segmented 3 photos")),
        "{:?}",
        state.log
    );
}
