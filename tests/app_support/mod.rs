//! Shared by the app tests that open a twin project in a viewer (`app_add_survey`,
//! `app_project_watch`): a new project holding one survey with a one-Gaussian model, open in
//! an `AppState` at that survey. Needs `mod project_support;` beside it (the model).

use std::path::Path;
use std::sync::Arc;

use damage_twin::app::settings::Settings;
use damage_twin::app::state::{AppState, LoadedSurvey, TimelineView};
use damage_twin::timeline::Twin;

use crate::project_support::one_gaussian;

/// Creates the project `project` with survey `survey` (dated 2024-06-01, its dataset
/// `dataset`) and a one-Gaussian model, saves it, and opens it in a viewer at that survey.
pub fn viewer_on_one_survey(project: &Path, survey: &str, dataset: &Path) -> AppState {
    let mut twin = Twin::create(project).expect("creates");
    twin.add_survey(survey, "2024-06-01", dataset)
        .expect("adds the survey");
    twin.save_model(survey, &one_gaussian()).expect("model");
    twin.save().expect("saves");
    let mut state = AppState::new(Settings::default());
    let shown = LoadedSurvey {
        splats: Some(Arc::new(one_gaussian())),
        dataset: None,
        edited: false,
    };
    let opened = Twin::open(project).expect("opens");
    state.timeline = Some(TimelineView::new(opened, 0, shown));
    state
}
