//! A commit is all or nothing (`Twin::commit`): every survey file it writes goes into a staging
//! folder per survey (`scene::run_folder::RunFolder`, beside `surveys/<name>/`), and the commit
//! ends, under the project's lock, with
//!
//! 1. the new `twin.ron` written and synced under a temporary name beside the old one,
//! 2. each staged folder put in its survey folder's place by two renames, the previous folder
//!    kept aside (`.<name>.replaced-<pid>`),
//! 3. the temporary `twin.ron` renamed over the old one: the commit point,
//! 4. the previous folders removed.
//!
//! A process killed before 3 leaves its temporary `twin.ron`: the next command (under the lock,
//! or when opening a project nobody holds) puts every previous folder back and removes the new
//! ones (`run_folder::undo_installs`), so the project is as it was. Killed after 3, the project
//! is as committed and only the previous folders are left to remove. Either way the next
//! command removes the staging folders and temporary files of dead processes and says so.

use std::path::{Path, PathBuf};

use crate::scene::project::PROJECT_FILE;
use crate::scene::run_folder::{
    RunFolder, abort_point, clean_leftovers, has_leftovers, process_alive, remove_dead_temp_files,
    temp_file_pid, undo_installs,
};
use crate::timeline::lock::{ProjectLock, Writer};
use crate::timeline::project_paths::SURVEYS_DIR;
use crate::timeline::twin::{TimelineError, Twin};

/// The survey folders a commit writes, staged until it ends. A copy of a project (`Clone`) is
/// no part of the commit in progress: it starts with none.
#[derive(Debug, Default)]
pub(crate) struct Staged {
    /// Inside `Twin::commit`: survey files are staged, not written in place.
    pub(crate) committing: bool,
    folders: Vec<(String, RunFolder)>,
}

impl Clone for Staged {
    fn clone(&self) -> Self {
        Staged::default()
    }
}

impl Twin {
    /// Where survey `name`'s file (or folder) `file` is written now: inside a `commit`, in the
    /// survey's staging folder (begun on first use; the survey's previous `file` is not carried
    /// over); outside one, in the survey folder itself (created when missing).
    pub fn output_path(&mut self, name: &str, file: &str) -> Result<PathBuf, TimelineError> {
        let target = self.survey_dir(name)?;
        // Refused when the file in place is a link out of the project, staged or not.
        let in_place = self.survey_file(name, file)?;
        if !self.staged.committing {
            std::fs::create_dir_all(&target).map_err(|e| super::io_error(&target, e))?;
            return Ok(in_place);
        }
        let survey = self.project.surveys[self.survey_index(name)?].name.clone();
        let position = match self.staged.folders.iter().position(|(n, _)| *n == survey) {
            Some(p) => p,
            None => {
                let folder = RunFolder::begin(&target, &[])?;
                self.staged.folders.push((survey, folder));
                self.staged.folders.len() - 1
            }
        };
        let folder = &mut self.staged.folders[position].1;
        folder.owns(file);
        Ok(folder.path(file))
    }

    /// Whether this is the project of a `commit` in progress (its survey files are staged): a
    /// change checked on a copy writes no record.
    pub fn is_committing(&self) -> bool {
        self.staged.committing
    }

    /// Survey `name`'s `file` is replaced by this change even where it writes none (a training
    /// record without a history): the previous one does not stay beside what was written.
    pub fn replaces(&mut self, name: &str, file: &str) -> Result<(), TimelineError> {
        let path = self.output_path(name, file)?;
        if !self.staged.committing && path.is_file() {
            std::fs::remove_file(&path).map_err(|e| super::io_error(&path, e))?;
        }
        Ok(())
    }

    /// The end of a commit (the caller holds the lock): the staged survey folders and `twin.ron`
    /// put in place as one (the protocol above).
    pub(super) fn write_commit(&mut self) -> Result<(), TimelineError> {
        self.staged.committing = false;
        let folders = std::mem::take(&mut self.staged.folders);
        if folders.is_empty() {
            return self.write_project();
        }
        let pending = self.project.save_pending(&self.file())?;
        abort_point("project-staged");
        let mut installed = Vec::new();
        for (_, folder) in folders {
            match folder.install() {
                Ok(done) => installed.push(done),
                Err(e) => {
                    installed.into_iter().rev().for_each(|i| i.undo());
                    return Err(e.into());
                }
            }
        }
        abort_point("folders-installed");
        if let Err(e) = pending.commit() {
            installed.into_iter().rev().for_each(|i| i.undo());
            return Err(e.into());
        }
        abort_point("project-renamed");
        installed.into_iter().for_each(|i| i.finish());
        self.base = Some(self.project.clone());
        Ok(())
    }

    /// Recovery after killed commits, for a process that holds the lock; tells the writer's
    /// `tell` what it cleaned.
    pub(super) fn recover_locked(&mut self) {
        let cleaned = recover(&self.dir);
        if let (false, Some(tell)) = (cleaned.is_empty(), self.writer.tell) {
            tell(&cleanup_message(&self.dir, &cleaned));
        }
        self.recovered.extend(cleaned);
    }
}

/// One line for the user about what a killed command left and this one cleaned.
pub fn cleanup_message(dir: &Path, cleaned: &[PathBuf]) -> String {
    let names: Vec<String> = cleaned
        .iter()
        .map(|p| p.strip_prefix(dir).unwrap_or(p).display().to_string())
        .collect();
    format!(
        "{}: cleaned up after a command that was killed: {}",
        dir.display(),
        names.join(", ")
    )
}

/// Recovery when opening a project: only when a dead process left something, and only when no
/// other process holds the project (then it is that writer's, or the next writer's, to clean).
/// Best effort: a project in a folder this process cannot write is read as it is.
pub(crate) fn recover_if_idle(dir: &Path) -> Vec<PathBuf> {
    if !leftovers_present(dir) {
        return Vec::new();
    }
    let writer = Writer::new("opening the project").waiting(std::time::Duration::ZERO);
    match ProjectLock::acquire(dir, &writer) {
        Ok(_lock) => recover(dir),
        Err(_) => Vec::new(),
    }
}

/// The temporary `twin.ron` of a dead process: the commit it belongs to did not reach its
/// commit point.
fn dead_project_temps(dir: &Path) -> Vec<(PathBuf, u32)> {
    let prefix = format!(".{PROJECT_FILE}.");
    std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|entry| {
            let name = entry.file_name().to_string_lossy().into_owned();
            let pid = temp_file_pid(&name).filter(|_| name.starts_with(&prefix))?;
            (!process_alive(pid)).then(|| (entry.path(), pid))
        })
        .collect()
}

fn leftovers_present(dir: &Path) -> bool {
    !dead_project_temps(dir).is_empty() || has_leftovers(&dir.join(SURVEYS_DIR))
}

/// Rolls back the commits of dead processes that did not reach their commit point, then removes
/// every leftover of dead processes. Returns what it put back or removed.
fn recover(dir: &Path) -> Vec<PathBuf> {
    let surveys = dir.join(SURVEYS_DIR);
    let mut cleaned = Vec::new();
    for (temp, pid) in dead_project_temps(dir) {
        cleaned.extend(undo_installs(&surveys, pid));
        // Removed only once every folder is back: a kill while undoing is undone again.
        if std::fs::remove_file(&temp).is_ok() {
            cleaned.push(temp);
        }
    }
    cleaned.extend(clean_leftovers(&surveys));
    cleaned.extend(remove_dead_temp_files(dir, 0));
    cleaned
}
