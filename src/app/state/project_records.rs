//! What the project panel says of the open twin's frame: its georeference (source, origin,
//! residual, how far its scale can be trusted) and each COLMAP-registered survey's residual.
//! Read from the project's files when the project's surveys change (not every frame).

use super::AppState;
use crate::timeline::Twin;
use crate::timeline::georeference::TwinGeoreference;

/// The open project's georeference and registration records, as last read.
#[derive(Clone, Debug)]
pub struct ProjectRecords {
    /// The surveys (name and dataset) they were read for: read again when these change.
    key: Vec<(String, std::path::PathBuf)>,
    /// The georeference, none, or why it could not be read.
    pub georeference: Result<Option<TwinGeoreference>, String>,
    /// Survey name and its registration's residual, for each survey registered by COLMAP.
    pub registrations: Vec<(String, String)>,
}

fn key_of(twin: &Twin) -> Vec<(String, std::path::PathBuf)> {
    twin.project
        .surveys
        .iter()
        .map(|s| (s.name.clone(), s.dataset.clone()))
        .collect()
}

impl ProjectRecords {
    pub fn read(twin: &Twin) -> ProjectRecords {
        let registrations = twin
            .project
            .surveys
            .iter()
            .filter_map(|s| match twin.load_registration(&s.name) {
                Ok(Some(record)) => Some((s.name.clone(), record.describe())),
                Ok(None) => None,
                Err(e) => Some((s.name.clone(), format!("registration unreadable: {e}"))),
            })
            .collect();
        ProjectRecords {
            key: key_of(twin),
            georeference: twin.georeference().map_err(|e| e.to_string()),
            registrations,
        }
    }
}

impl AppState {
    /// Reads the open project's records again when its surveys changed; true when it did.
    pub(super) fn refresh_project_records(&mut self) -> bool {
        let Some(timeline) = &mut self.timeline else {
            return false;
        };
        if timeline
            .records
            .as_ref()
            .is_some_and(|r| r.key == key_of(&timeline.twin))
        {
            return false;
        }
        timeline.records = Some(ProjectRecords::read(&timeline.twin));
        true
    }
}
