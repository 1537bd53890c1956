//! Unit tests of the twin project: surveys, models, metrics and histories saved and read back.

use super::*;

#[test]
fn civil_dates_match_known_days() {
    assert_eq!(civil_date(0), "1970-01-01");
    assert_eq!(civil_date(19_723), "2024-01-01");
    assert_eq!(civil_date(20_517), "2026-03-05");
    assert_eq!(today().len(), 10);
}

#[test]
fn relative_paths_climb_out_of_the_project() {
    let p = relative_path(Path::new("/data/lund"), Path::new("/work/twin")).unwrap();
    assert_eq!(p, PathBuf::from("../../data/lund"));
    let p = relative_path(Path::new("/work/twin/s1"), Path::new("/work/twin")).unwrap();
    assert_eq!(p, PathBuf::from("s1"));
}

#[test]
fn surveys_keep_their_models_and_paths_are_relative() {
    let root = tempfile::tempdir().unwrap();
    let data = root.path().join("data/survey-1");
    std::fs::create_dir_all(&data).unwrap();
    let dir = root.path().join("twin");
    let mut twin = Twin::create(&dir).unwrap();
    twin.add_survey("survey-1", "2026-03-01", &data).unwrap();
    twin.add_survey("survey-2", "2026-09-01", &data).unwrap();
    assert_eq!(
        twin.survey("survey-1").unwrap().dataset,
        PathBuf::from("../data/survey-1")
    );
    let mut splats = Splats::empty(0, 0);
    splats.push(
        glam::Vec3::ZERO,
        glam::Vec3::ZERO,
        glam::Quat::IDENTITY,
        0.0,
        &[0.1, 0.2, 0.3],
        &[],
        0,
        0,
    );
    twin.save_model("survey-1", &splats).unwrap();
    let first = std::fs::read(dir.join("surveys/survey-1/model.ply")).unwrap();
    splats.means[0] = glam::Vec3::ONE;
    twin.save_model("survey-2", &splats).unwrap();
    twin.save_metrics("survey-2", &serde_json::json!({"psnr": 30.0}))
        .unwrap();
    twin.save().unwrap();

    let mut reopened = Twin::open(&dir.join(PROJECT_FILE)).unwrap();
    assert_eq!(reopened, twin);
    assert_eq!(
        std::fs::read(dir.join("surveys/survey-1/model.ply")).unwrap(),
        first,
        "a later survey's save leaves the earlier model's bytes as they were"
    );
    assert_eq!(
        reopened.survey_of_dataset(&data).map(|s| s.name.as_str()),
        Some("survey-1")
    );
    let loaded = reopened.load_model("survey-2").unwrap().unwrap();
    assert_eq!(loaded.means[0], glam::Vec3::ONE);
    assert!(matches!(
        Twin::create(&dir),
        Err(TimelineError::Exists { .. })
    ));
    assert_eq!(reopened.unused_name("survey-1"), "survey-1-2");
    assert!(matches!(
        reopened.load_metrics("survey-2").unwrap(),
        Some(SurveyRecord::Other(_))
    ));
    assert_eq!(reopened.load_metrics("survey-1").unwrap(), None);

    // Training histories: none until saved; a damaged file is an error naming it.
    assert!(reopened.load_history("survey-1").unwrap().is_none());
    let mut history = History::default();
    history.push_eval(crate::train::history::EvalSample {
        wall_s: 1.0,
        step: 10,
        psnr: 24.0,
    });
    reopened.save_history("survey-1", &history).unwrap();
    let back = reopened.load_history("survey-1").unwrap().unwrap();
    assert_eq!(back.evals, history.evals);
    std::fs::write(dir.join("surveys/survey-1").join(HISTORY_FILE), "{").unwrap();
    let error = reopened.load_history("survey-1").unwrap_err().to_string();
    assert!(error.contains(HISTORY_FILE), "{error}");
}
