//! The side panels: each a small type with one `ui(&mut self, ui, &AppState, &mut Vec<Command>)`
//! method that reads the state and queues commands (rerun style). Panels never change the state
//! directly and never talk to each other.

pub mod add_survey;
pub mod charts;
pub mod colmap_log;
pub mod log;
pub mod new_twin;
pub mod project;
pub mod regions;
pub mod selection;
pub mod stats;
pub mod timeline;
pub mod training;
pub mod view;

pub use add_survey::AddSurveyPanel;
pub use charts::ChartsPanel;
pub use colmap_log::ColmapLogPanel;
pub use log::LogPanel;
pub use new_twin::NewTwinPanel;
pub use project::ProjectPanel;
pub use regions::RegionsPanel;
pub use selection::SelectionPanel;
pub use stats::StatsPanel;
pub use timeline::TimelinePanel;
pub use training::TrainingPanel;
pub use view::ViewPanel;

use crate::app::commands::{Command, DialogKind};
use crate::app::settings::Settings;
use crate::app::state::AppState;

/// Edits a copy of the settings with `edit`; queues an update when anything changed.
pub(crate) fn edit_settings(
    state: &AppState,
    commands: &mut Vec<Command>,
    edit: impl FnOnce(&mut Settings),
) {
    let mut settings = state.settings.clone();
    edit(&mut settings);
    if settings != state.settings {
        commands.push(Command::UpdateSettings(Box::new(settings)));
    }
}

/// One row of a dialog's grid: `label`, a path typed into `text` (a grey `hint` while empty) and,
/// with `choose`, a "Choose…" button opening that file dialog.
pub(crate) fn path_row(
    ui: &mut egui::Ui,
    label: &str,
    text: &mut String,
    hint: &str,
    choose: Option<DialogKind>,
    commands: &mut Vec<Command>,
) {
    ui.label(label);
    ui.horizontal(|ui| {
        ui.add(
            egui::TextEdit::singleline(text)
                .hint_text(hint)
                .desired_width(280.0),
        );
        if let Some(dialog) = choose
            && ui.button("Choose…").clicked()
        {
            commands.push(Command::ShowDialog(dialog));
        }
    });
    ui.end_row();
}
