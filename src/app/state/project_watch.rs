//! An open project watched for other writers: who holds its lock (a `twin update` in a terminal,
//! another viewer), shown in the timeline strip, and its `twin.ron` read again when another
//! process changed it, so the viewer never shows a stale record as current. Checked once a
//! second, from the file's modification time: cheap enough for every frame's poll.

use std::path::Path;
use std::time::{Duration, Instant, SystemTime};

use super::AppState;
use crate::timeline::Twin;
use crate::timeline::lock::{Holder, current_holder};

/// How often the project's lock and file are looked at.
const CHECK_EVERY: Duration = Duration::from_secs(1);

/// What the viewer last saw of its project's files.
#[derive(Debug)]
pub struct ProjectWatch {
    checked: Instant,
    modified: Option<SystemTime>,
    /// Another process writing the project now.
    pub holder: Option<Holder>,
}

impl ProjectWatch {
    pub fn new(twin: &Twin) -> ProjectWatch {
        ProjectWatch {
            checked: Instant::now(),
            modified: modified(&twin.file()),
            holder: None,
        }
    }
}

fn modified(file: &Path) -> Option<SystemTime> {
    std::fs::metadata(file).and_then(|m| m.modified()).ok()
}

impl AppState {
    /// Looks at the open project's lock and `twin.ron` (at most once a second); reads the project
    /// again when another process changed it and no job of the viewer's is running on it.
    /// Returns true when what the timeline shows changed.
    pub(super) fn poll_project_watch(&mut self) -> bool {
        let Some(timeline) = &mut self.timeline else {
            return false;
        };
        if timeline.watch.checked.elapsed() < CHECK_EVERY {
            return false;
        }
        timeline.watch.checked = Instant::now();
        let holder = current_holder(timeline.twin.dir());
        let mut changed = holder != timeline.watch.holder;
        timeline.watch.holder = holder;
        let now = modified(&timeline.twin.file());
        if now == timeline.watch.modified || timeline.job.is_some() {
            return changed;
        }
        timeline.watch.modified = now;
        // This viewer's own saves change the file too: only a different record is news.
        match Twin::open(timeline.twin.dir()) {
            Ok(fresh) if fresh.project == timeline.twin.project => {}
            Ok(fresh) => {
                let surveys = fresh.project.surveys.len();
                timeline.twin = fresh;
                // Models read before the change may be stale: read again when shown, but the
                // one on screen (and its edits) stays until the user steps away from it.
                let current = timeline.current;
                timeline.loaded.retain(|&index, _| index == current);
                timeline.compare = timeline.compare.filter(|&c| c < surveys);
                changed = true;
                self.log_line(
                    "the project changed on disk (another process wrote it): its record was read \
                     again; surveys are read again when shown",
                );
            }
            Err(e) => self.log_line(format!("the project changed on disk: {e}")),
        }
        changed
    }
}
