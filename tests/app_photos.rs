//! The viewer's flows from photos (issue 40 §5), driven headless through the commands their
//! dialogs queue, with a fake `colmap` (`colmap_support`): "New twin from photos…" posing a
//! folder into a dataset and a new project that opens; "Add survey from photos…" registering a
//! later survey's photos into the twin's posed survey and adding it by the add-survey job; a
//! cancel while COLMAP runs leaving no dataset, staging folder, log or project; a COLMAP failure
//! shown in one line with its last lines and its log one click away; the project panel's
//! georeference and registration records; and a refusal line cleared once the fields change.
#![cfg(feature = "app")]

mod colmap_support;

use std::time::{Duration, Instant};

use colmap_support::{Setup, fake_colmap_in_process, noise_png};
use damage_twin::app::commands::Command;
use damage_twin::app::settings::Settings;
use damage_twin::app::state::{AppState, colmap_log_of};
use damage_twin::app::twin_form::NewTwinForm;
use damage_twin::scene::sfm::georef::{GeorefSource, Georeference};
use damage_twin::scene::similarity::Similarity;
use damage_twin::timeline::Twin;

/// Polls until `done`, at most 30 s.
fn poll_until(state: &mut AppState, what: &str, done: impl Fn(&AppState) -> bool) {
    let start = Instant::now();
    while !done(state) {
        state.poll();
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "timed out waiting for {what}; log: {:?}",
            state.log
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// What is left in the test's folder named like `name` (datasets, staging folders, logs).
fn left_named(setup: &Setup, name: &str) -> Vec<String> {
    std::fs::read_dir(setup.dir.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(name))
        .collect()
}

/// Photos `a`, `b`, `c` (the names of the fake model's images) in `photos`.
fn photos_like_the_model(setup: &Setup) {
    let photos = setup.path("photos");
    std::fs::create_dir_all(&photos).unwrap();
    for (i, name) in ["a.png", "b.png", "c.png"].iter().enumerate() {
        noise_png(&photos.join(name), 20 + i as u64);
    }
}

/// A fake COLMAP for `pose`: its mapper writes survey 1's model as component 0; `extra` (sh)
/// runs first for each command (`$cmd`).
fn fake_pose_colmap(setup: &Setup, extra: &str) {
    let model = setup.path("s1/sparse/0");
    let mapper = format!(
        "if [ \"$cmd\" = feature_extractor ]; then echo 'Processed file [3/3]'; fi\n{extra}\n\
         if [ \"$cmd\" = mapper ]; then mkdir -p \"$out/0\"; cp {}/*.bin \"$out/0/\"; exit 0; fi",
        model.display()
    );
    setup.fake_colmap(&model, &mapper);
}

fn new_twin_form(setup: &Setup) -> NewTwinForm {
    let mut form = NewTwinForm {
        train: false,
        ..NewTwinForm::default()
    };
    form.choose_photos(&setup.path("photos"));
    form
}

fn start_new_twin(setup: &Setup) -> AppState {
    let mut state = AppState::new(Settings::default());
    state.apply(Command::OpenNewTwin);
    state.apply(Command::EditNewTwin(Box::new(new_twin_form(setup))));
    state.apply(Command::NewTwinFromPhotos);
    assert!(
        state.new_twin.as_ref().is_some_and(|d| d.run.is_some()),
        "{:?}",
        state.log
    );
    state
}

fn dialog_error(state: &AppState) -> String {
    let dialog = state.new_twin.as_ref().expect("the dialog stays open");
    dialog.form.error.clone().expect("a refusal line")
}

#[test]
fn new_twin_from_photos_poses_them_and_opens_the_project() {
    fake_colmap_in_process();
    let setup = Setup::new();
    photos_like_the_model(&setup);
    fake_pose_colmap(&setup, "");
    let form = new_twin_form(&setup);
    assert!(form.dataset.ends_with("photos-posed"), "{}", form.dataset);
    assert!(form.project.ends_with("photos-twin"), "{}", form.project);
    assert_eq!(form.survey, "photos");
    let mut state = start_new_twin(&setup);
    poll_until(&mut state, "the project to open", |s| s.timeline.is_some());

    assert!(state.new_twin.is_none(), "the dialog closed");
    let dataset = setup.path("photos-posed");
    assert!(dataset.join("sparse/0/images.bin").is_file());
    assert!(dataset.join("pose.json").is_file());
    let twin = Twin::open(&setup.path("photos-twin")).unwrap();
    assert_eq!(twin.project.surveys.len(), 1);
    assert_eq!(twin.project.surveys[0].name, "photos");
    let timeline = state.timeline.as_ref().unwrap();
    assert_eq!(timeline.twin.project.surveys[0].name, "photos");
    let scene = state.scene.as_ref().unwrap();
    assert_eq!(scene.dataset.as_ref().unwrap().views.len(), 3);
    assert!(
        state
            .log
            .iter()
            .any(|l| l.starts_with("posed 3 of 3 photos")),
        "{:?}",
        state.log
    );
    // COLMAP's log is the dataset's now.
    assert_eq!(
        colmap_log_of(&dataset),
        Some(dataset.join("colmap/colmap.log"))
    );
}

#[test]
fn cancelling_new_twin_from_photos_stops_colmap_and_leaves_nothing() {
    fake_colmap_in_process();
    let setup = Setup::new();
    photos_like_the_model(&setup);
    // The mapper runs silently for long, as COLMAP's does.
    fake_pose_colmap(&setup, "if [ \"$cmd\" = mapper ]; then exec sleep 30; fi");
    let mut state = start_new_twin(&setup);
    let calls = setup.path("bin/colmap.calls");
    poll_until(&mut state, "the mapper to start", |_| {
        std::fs::read_to_string(&calls).is_ok_and(|c| c.contains("mapper"))
    });
    let dataset = setup.path("photos-posed");
    let live = colmap_log_of(&dataset).expect("the running job's log is one click away");
    assert!(
        std::fs::read_to_string(&live)
            .unwrap()
            .contains("exhaustive_matcher")
    );
    let progress = state.new_twin.as_ref().unwrap().run.as_ref().unwrap();
    assert!(
        progress.progress.is_some(),
        "COLMAP's stages reached the dialog"
    );
    let cancelled = Instant::now();
    state.apply(Command::CancelNewTwin);
    poll_until(&mut state, "the cancel", |s| {
        s.new_twin.as_ref().is_some_and(|d| d.run.is_none())
    });
    assert!(cancelled.elapsed() < Duration::from_secs(10));
    assert!(dialog_error(&state).contains("cancelled"));
    assert_eq!(left_named(&setup, "photos-"), Vec::<String>::new());
    assert!(colmap_log_of(&dataset).is_none());
    assert!(state.timeline.is_none());
}

#[test]
fn a_failing_colmap_is_one_red_line_with_its_last_lines_and_its_log() {
    fake_colmap_in_process();
    let setup = Setup::new();
    photos_like_the_model(&setup);
    fake_pose_colmap(
        &setup,
        "if [ \"$cmd\" = exhaustive_matcher ]; then \
         echo 'F0101 matching.cc:1] Check failed: matches' >&2; exit 134; fi",
    );
    let mut state = start_new_twin(&setup);
    poll_until(&mut state, "the failure", |s| {
        s.new_twin.as_ref().is_some_and(|d| d.run.is_none())
    });
    let error = dialog_error(&state);
    assert!(error.contains("Check failed: matches"), "{error}");
    assert!(error.contains("exhaustive_matcher"), "{error}");
    assert!(error.contains("exit status: 134"), "{error}");
    assert!(!error.contains('\n'), "one line: {error}");
    // No dataset; the log kept beside where it would have been, offered by the dialog.
    let dataset = setup.path("photos-posed");
    assert!(!dataset.exists());
    assert!(!setup.path("photos-twin/twin.ron").exists());
    let shown = state
        .new_twin
        .as_ref()
        .unwrap()
        .last_dataset
        .clone()
        .unwrap();
    state.apply(Command::ShowColmapLog(Some(shown)));
    let log = colmap_log_of(state.colmap_log.as_ref().unwrap()).expect("the kept log");
    assert!(log.ends_with("photos-posed.pose-failed.log"), "{log:?}");
    assert!(
        std::fs::read_to_string(&log)
            .unwrap()
            .contains("Check failed")
    );

    // A refusal stays until the fields change, then goes.
    let mut edited = state.new_twin.as_ref().unwrap().form.clone();
    state.apply(Command::EditNewTwin(Box::new(edited.clone())));
    assert!(state.new_twin.as_ref().unwrap().form.error.is_some());
    edited.survey = "first".into();
    state.apply(Command::EditNewTwin(Box::new(edited)));
    assert_eq!(state.new_twin.as_ref().unwrap().form.error, None);
}

/// The viewer on the setup's project (survey 1 posed), as opened from its folder.
fn viewer_on_project(setup: &Setup) -> AppState {
    let mut state = AppState::new(Settings::default());
    state.apply(Command::Open(setup.path("proj")));
    poll_until(&mut state, "the project to open", |s| {
        s.timeline.as_ref().is_some_and(|t| t.records.is_some())
    });
    state
}

fn surveys(state: &AppState) -> Vec<String> {
    let timeline = state.timeline.as_ref().unwrap();
    timeline
        .twin
        .project
        .surveys
        .iter()
        .map(|s| s.name.clone())
        .collect()
}

fn add_survey_from_photos(state: &mut AppState, setup: &Setup) {
    state.apply(Command::OpenAddSurveyFromPhotos);
    state.apply(Command::ChooseSurveyPhotos(setup.path("new")));
    let mut form = state.add_survey.clone().expect("the dialog");
    assert!(form.from_photos);
    assert!(form.dataset.ends_with("new-registered"), "{}", form.dataset);
    form.name = "s2".into();
    form.date = "2026-02-01".into();
    state.apply(Command::EditAddSurvey(Box::new(form)));
    state.apply(Command::AddSurvey);
}

#[test]
fn add_survey_from_photos_registers_them_and_the_panel_shows_the_records() {
    fake_colmap_in_process();
    let setup = Setup::new();
    setup.fake_colmap(&setup.continued_model(true), "");
    // Survey 1's dataset georeferenced from GPS (as `pose` would have written it).
    let georef = Georeference {
        source: GeorefSource::Gps,
        latitude: 55.7,
        longitude: 13.2,
        altitude: 40.0,
        similarity: Similarity {
            scale: 2.0,
            rotation: [0.0, 0.0, 0.0, 1.0],
            translation: [0.0; 3],
        },
        rms_m: 3.5,
        used: vec!["a.png".into(), "b.png".into(), "c.png".into()],
        rejected: Vec::new(),
        baseline_m: 40.0,
        scale_uncertainty: 0.05,
        model_doubt: None,
    };
    georef.write(&setup.path("s1")).unwrap();
    let mut state = viewer_on_project(&setup);
    let records = state.timeline.as_ref().unwrap().records.clone().unwrap();
    let shown = records
        .georeference
        .unwrap()
        .expect("survey 1's georeference");
    assert_eq!(shown.georeference.rms_m, 3.5);
    assert!(records.registrations.is_empty());

    add_survey_from_photos(&mut state, &setup);
    poll_until(&mut state, "the add", |s| {
        s.timeline.as_ref().is_some_and(|t| t.job.is_none())
    });
    assert_eq!(surveys(&state), ["s1", "s2"], "{:?}", state.log);
    assert!(state.add_survey.is_none(), "the dialog closed");
    assert!(setup.path("new-registered/register.json").is_file());
    let twin = Twin::open(&setup.path("proj")).unwrap();
    assert!(twin.load_registration("s2").unwrap().is_some());
    // The panel's records are read again for the new survey.
    state.poll();
    let records = state.timeline.as_ref().unwrap().records.clone().unwrap();
    assert_eq!(records.registrations.len(), 1);
    assert!(
        records.registrations[0]
            .1
            .contains("1 of 2 photos registered into survey s1's model"),
        "{:?}",
        records.registrations
    );
}

#[test]
fn cancelling_add_survey_from_photos_leaves_no_dataset_and_no_survey() {
    fake_colmap_in_process();
    let setup = Setup::new();
    setup.fake_colmap(
        &setup.continued_model(true),
        "if [ \"$cmd\" = mapper ]; then exec sleep 30; fi",
    );
    let mut state = viewer_on_project(&setup);
    add_survey_from_photos(&mut state, &setup);
    let calls = setup.path("bin/colmap.calls");
    poll_until(&mut state, "the mapper to start", |_| {
        std::fs::read_to_string(&calls).is_ok_and(|c| c.contains("mapper"))
    });
    state.apply(Command::CancelTimelineJob);
    poll_until(&mut state, "the cancel", |s| {
        s.timeline.as_ref().is_some_and(|t| t.job.is_none())
    });
    let form = state.add_survey.as_ref().expect("the dialog stays open");
    assert!(
        form.error
            .as_deref()
            .is_some_and(|e| e.contains("cancelled")),
        "{:?}",
        form.error
    );
    assert_eq!(left_named(&setup, "new-registered"), Vec::<String>::new());
    assert_eq!(surveys(&state), ["s1"]);
    assert_eq!(
        Twin::open(&setup.path("proj"))
            .unwrap()
            .project
            .surveys
            .len(),
        1
    );
    assert_eq!(
        std::fs::read_to_string(setup.path("s1/colmap/database.db")).unwrap(),
        "the old database"
    );
}

#[test]
fn the_add_survey_refusal_is_cleared_when_the_fields_change() {
    let setup = Setup::new();
    let mut state = viewer_on_project(&setup);
    state.apply(Command::OpenAddSurvey);
    state.apply(Command::ChooseSurveyDataset(setup.path("s1")));
    let mut form = state.add_survey.clone().unwrap();
    form.name = String::new();
    state.apply(Command::EditAddSurvey(Box::new(form.clone())));
    state.apply(Command::AddSurvey);
    let refused = state.add_survey.clone().unwrap();
    assert!(refused.error.is_some(), "an empty name is refused");
    // Submitting the same fields (the panel does, every frame) keeps the line.
    state.apply(Command::EditAddSurvey(Box::new(refused.clone())));
    assert!(state.add_survey.as_ref().unwrap().error.is_some());
    // Typing a name: the line was about the fields as they were.
    let mut typed = refused;
    typed.name = "s2".into();
    state.apply(Command::EditAddSurvey(Box::new(typed)));
    assert_eq!(state.add_survey.as_ref().unwrap().error, None);
}
