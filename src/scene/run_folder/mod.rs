//! A run's outputs replaced as one: every file of the run is written into a staging folder
//! beside the target, and the staging folder then takes the target's place in one atomic step
//! (Linux `renameat2(RENAME_EXCHANGE)`; elsewhere two renames, the gap between them repaired by
//! the next run). A kill at any moment leaves either the previous run's folder intact or the new
//! run's folder complete — never a new `model.ply` beside the old `metrics.json`. Anything else
//! the user kept in the folder (renders, notes, subfolders) is carried over as a tree of hard
//! links, so the user's files are in the folder whichever side of the swap a kill lands on.
//! Files the run owns (`begin`'s outputs: what it may write) are never carried, written or not:
//! an `appearance.json` of an earlier `--appearance` run does not outlive it beside a model
//! trained without.
//!
//! Stale staging folders of killed runs (their process gone) are removed when the next run on
//! the same target begins (`clean_leftovers` for every target in a folder). A twin project
//! commits several folders and its project file as one (`install`, then the project file's
//! rename, then `Installed::finish`; `undo_installs` rolls back a commit killed before its
//! project file was renamed).

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use crate::scene::SceneError;

const STAGING_TAG: &str = ".staging-";
const OLD_TAG: &str = ".replaced-";

/// Test hook: `DAMAGE_TWIN_ABORT_AT=<point>` aborts the process (no destructors, like kill -9) at
/// that point of the commit, so tests can check what a kill there leaves behind.
const ABORT_ENV: &str = "DAMAGE_TWIN_ABORT_AT";

pub fn abort_point(point: &str) {
    if std::env::var(ABORT_ENV).is_ok_and(|p| p == point) {
        std::process::abort();
    }
}

/// The staging folder of one run; `commit` puts it in the target's place.
#[derive(Debug)]
pub struct RunFolder {
    target: PathBuf,
    staging: PathBuf,
    /// The names the run owns (a name ending in `*`: every name it begins): never carried over.
    outputs: Vec<String>,
}

/// A run folder in its target's place, the previous folder kept aside until `finish` (or put
/// back by `undo`).
#[derive(Debug)]
pub struct Installed {
    target: PathBuf,
    staging: PathBuf,
    old: Option<PathBuf>,
}

impl RunFolder {
    /// Creates the staging folder beside `target` (creating `target`'s parent if needed),
    /// after cleaning up what killed runs left there. `outputs` are the names of every file or
    /// folder the run may write (a trailing `*` matches every name it begins): they are never
    /// carried over from the previous folder, so none outlives the run that wrote it. Fails now,
    /// before any work, when the place is not writable.
    pub fn begin(target: &Path, outputs: &[&str]) -> Result<RunFolder, SceneError> {
        // A link to a folder: the run replaces the folder it points at, not the link.
        let resolved;
        let target = if fs::symlink_metadata(target).is_ok_and(|m| m.file_type().is_symlink()) {
            resolved = fs::canonicalize(target).map_err(|e| SceneError::io(target, e))?;
            resolved.as_path()
        } else {
            target
        };
        let name = target
            .file_name()
            .ok_or_else(|| SceneError::invalid(target, "not a folder name"))?
            .to_string_lossy()
            .into_owned();
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        fs::create_dir_all(&parent).map_err(|e| SceneError::io(&parent, e))?;
        if target.exists() && !target.is_dir() {
            return Err(SceneError::invalid(target, "exists and is not a folder"));
        }
        // What killed runs on this target left (`clean_leftovers` for it alone).
        clean(&parent, Some(&name));
        let staging = staging_path(&parent, &name);
        if staging.exists() {
            fs::remove_dir_all(&staging).map_err(|e| SceneError::io(&staging, e))?;
        }
        fs::create_dir(&staging).map_err(|e| SceneError::io(&staging, e))?;
        Ok(RunFolder {
            target: target.to_path_buf(),
            staging,
            outputs: outputs.iter().map(|o| o.to_string()).collect(),
        })
    }

    /// The run owns `name` too (see `begin`).
    pub fn owns(&mut self, name: &str) {
        if !self.outputs.iter().any(|o| o == name) {
            self.outputs.push(name.to_string());
        }
    }

    fn is_output(&self, name: &str) -> bool {
        self.outputs.iter().any(|o| match o.strip_suffix('*') {
            Some(prefix) => name.starts_with(prefix),
            None => o == name,
        })
    }

    /// Where the run writes its file `name`.
    pub fn path(&self, name: &str) -> PathBuf {
        self.staging.join(name)
    }

    /// The staging folder itself, for writers that take a folder.
    pub fn staging(&self) -> &Path {
        &self.staging
    }

    /// The folder the run's files end up in.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Puts the staged files in the target's place, carrying over what else the target held.
    /// The files must already be complete (written and closed); this syncs them.
    pub fn commit(self) -> Result<(), SceneError> {
        self.prepare()?;
        if !self.target.exists() {
            abort_point("before-swap");
            fs::rename(&self.staging, &self.target).map_err(|e| SceneError::io(&self.target, e))?;
            abort_point("after-swap");
            sync_parent(&self.target);
            return Ok(());
        }
        abort_point("before-swap");
        let old = swap(&self.staging, &self.target)?;
        abort_point("after-swap");
        sync_parent(&self.target);
        // The previous run's files and the links to the user's.
        let _ = fs::remove_dir_all(&old);
        Ok(())
    }

    /// `commit` up to the removal of the previous folder, which stays aside (`.<name>.replaced-
    /// <pid>`) until `Installed::finish`, so that a commit of several folders and a project file
    /// can still be undone. Two renames, never an exchange: which side of them a kill lands on
    /// reads from the names alone (`undo_installs`).
    pub fn install(self) -> Result<Installed, SceneError> {
        self.prepare()?;
        // A target that did not exist yet is an empty folder to put back, so that an undone
        // install leaves no new folder either.
        if !self.target.exists() {
            fs::create_dir(&self.target).map_err(|e| SceneError::io(&self.target, e))?;
        }
        let old = old_path(&self.staging);
        fs::rename(&self.target, &old).map_err(|e| SceneError::io(&self.target, e))?;
        let old = Some(old);
        abort_point("between-renames");
        if let Err(e) = fs::rename(&self.staging, &self.target) {
            if let Some(old) = &old {
                let _ = fs::rename(old, &self.target);
            }
            return Err(SceneError::io(&self.target, e));
        }
        sync_parent(&self.target);
        Ok(Installed {
            target: self.target.clone(),
            staging: self.staging.clone(),
            old,
        })
    }

    /// Syncs the staged files and carries over the user's other entries (a tree of hard links),
    /// so the swap loses nothing and they are in the target on either side of it.
    fn prepare(&self) -> Result<(), SceneError> {
        let staged = list(&self.staging).map_err(|e| SceneError::io(&self.staging, e))?;
        for name in &staged {
            let path = self.staging.join(name);
            if path.is_file() {
                fs::File::open(&path)
                    .and_then(|f| f.sync_all())
                    .map_err(|e| SceneError::io(&path, e))?;
            }
        }
        if !self.target.exists() {
            return Ok(());
        }
        let kept = list(&self.target).map_err(|e| SceneError::io(&self.target, e))?;
        for name in kept
            .iter()
            .filter(|n| !staged.contains(n) && !self.is_output(n))
        {
            abort_point("carrying");
            link_tree(&self.target.join(name), &self.staging.join(name))?;
        }
        Ok(())
    }
}

impl Installed {
    /// The previous folder removed: the new one stays.
    pub fn finish(self) {
        if let Some(old) = &self.old {
            let _ = fs::remove_dir_all(old);
        }
    }

    /// The previous folder put back in the target's place; the new one removed.
    pub fn undo(self) {
        if fs::rename(&self.target, &self.staging).is_ok() {
            let _ = fs::remove_dir_all(&self.staging);
        }
        if let Some(old) = &self.old {
            let _ = fs::rename(old, &self.target);
        }
    }
}

/// Undoes the installs (`RunFolder::install`) of process `pid`, killed before it finished them,
/// in `parent`: each previous folder kept aside goes back in its target's place, and the new
/// folder back to its staging name, for `clean_leftovers` to remove. Each step is one rename,
/// so a kill while undoing leaves a state this undoes again. Returns the targets put back.
pub fn undo_installs(parent: &Path, pid: u32) -> Vec<PathBuf> {
    let mut restored = Vec::new();
    for entry in list(parent).unwrap_or_default() {
        let Some((name, entry_pid, true)) = leftover(&entry) else {
            continue;
        };
        if entry_pid != pid {
            continue;
        }
        let target = parent.join(name);
        let staging = parent.join(format!(".{name}{STAGING_TAG}{pid}"));
        if fs::symlink_metadata(&target).is_ok() && !staging.exists() {
            let _ = fs::rename(&target, &staging);
        }
        if fs::rename(parent.join(&entry), &target).is_ok() {
            restored.push(target);
        }
    }
    restored
}

/// Recreates `from` at `to` with hard links to its files (copies where linking fails), its
/// folders created anew and its symbolic links recreated, never followed.
fn link_tree(from: &Path, to: &Path) -> Result<(), SceneError> {
    let meta = fs::symlink_metadata(from).map_err(|e| SceneError::io(from, e))?;
    let result = if meta.is_dir() {
        fs::create_dir(to).map_err(|e| SceneError::io(to, e))?;
        for name in list(from).map_err(|e| SceneError::io(from, e))? {
            link_tree(&from.join(&name), &to.join(&name))?;
        }
        Ok(())
    } else if meta.file_type().is_symlink() {
        relink(from, to)
    } else {
        fs::hard_link(from, to).or_else(|_| fs::copy(from, to).map(|_| ()))
    };
    result.map_err(|e| SceneError::io(from, e))
}

#[cfg(unix)]
fn relink(from: &Path, to: &Path) -> io::Result<()> {
    std::os::unix::fs::symlink(fs::read_link(from)?, to)
}

#[cfg(not(unix))]
fn relink(from: &Path, to: &Path) -> io::Result<()> {
    fs::copy(from, to).map(|_| ())
}

/// The staging folder this process's run on the target `parent/name` writes into while it runs
/// (a viewer shows the log a running job writes there).
pub fn staging_path(parent: &Path, name: &str) -> PathBuf {
    parent.join(format!(".{name}{STAGING_TAG}{}", std::process::id()))
}

impl Drop for RunFolder {
    /// A run that fails or is cancelled before `commit` leaves nothing beside the target. After
    /// a commit the staging path holds the previous folder (already removed) or nothing; it
    /// only ever holds links to the user's files, never the files alone.
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.staging);
    }
}

/// Swaps the staging folder into the target's place; returns where the previous folder is.
fn swap(staging: &Path, target: &Path) -> Result<PathBuf, SceneError> {
    #[cfg(target_os = "linux")]
    if exchange(staging, target).is_ok() {
        return Ok(staging.to_path_buf());
    }
    // Two renames; a kill between them leaves no target, and the next `begin` puts the
    // previous folder back (`recover`).
    let old = old_path(staging);
    fs::rename(target, &old).map_err(|e| SceneError::io(target, e))?;
    fs::rename(staging, target).map_err(|e| SceneError::io(target, e))?;
    Ok(old)
}

fn old_path(staging: &Path) -> PathBuf {
    let name = staging
        .file_name()
        .map(|n| n.to_string_lossy().replace(STAGING_TAG, OLD_TAG))
        .unwrap_or_default();
    staging.with_file_name(name)
}

/// Atomic exchange of two paths (both must exist).
#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> io::Result<()> {
    use std::ffi::CString;
    use std::os::unix::ffi::OsStrExt;
    let a = CString::new(a.as_os_str().as_bytes())?;
    let b = CString::new(b.as_os_str().as_bytes())?;
    // SAFETY: both pointers are NUL-terminated strings that live across the call; renameat2
    // reads them and touches no other memory.
    let rc = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            a.as_ptr(),
            libc::AT_FDCWD,
            b.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

/// Cleans up after killed runs (their process gone) on every target in `parent`: a missing
/// target whose previous folder survives a two-rename swap is put back; stale staging and
/// replaced folders are removed; stale temporary files of `scene::atomic` inside each target
/// (and its subfolders) are removed. Best effort: a run must not fail because a dead run's
/// leftovers could not be removed. Returns what it removed or put back, for the user.
pub fn clean_leftovers(parent: &Path) -> Vec<PathBuf> {
    clean(parent, None)
}

fn clean(parent: &Path, only: Option<&str>) -> Vec<PathBuf> {
    let mut cleaned = Vec::new();
    let entries = list(parent).unwrap_or_default();
    for entry in &entries {
        let Some((name, pid, is_old)) = leftover(entry) else {
            continue;
        };
        if only.is_some_and(|o| o != name) || process_alive(pid) {
            continue;
        }
        let stale = parent.join(entry);
        let target = parent.join(name);
        if is_old && fs::symlink_metadata(&target).is_err() {
            if fs::rename(&stale, &target).is_ok() {
                cleaned.push(target);
            }
            continue;
        }
        if fs::remove_dir_all(&stale).is_ok() {
            cleaned.push(stale);
        }
    }
    for entry in &entries {
        let target = parent.join(entry);
        if only.is_some_and(|o| o != entry) || !target.is_dir() || leftover(entry).is_some() {
            continue;
        }
        cleaned.extend(remove_dead_temp_files(&target, 1));
    }
    cleaned
}

/// Whether `clean_leftovers` would find anything in `parent` (without changing anything).
pub fn has_leftovers(parent: &Path) -> bool {
    list(parent)
        .unwrap_or_default()
        .iter()
        .any(|entry| match leftover(entry) {
            Some((_, pid, _)) => !process_alive(pid),
            None => has_dead_temp_files(&parent.join(entry), 1),
        })
}

fn has_dead_temp_files(dir: &Path, depth: u32) -> bool {
    if !fs::symlink_metadata(dir).is_ok_and(|m| m.is_dir()) {
        return false;
    }
    list(dir)
        .unwrap_or_default()
        .iter()
        .any(|entry| match temp_file_pid(entry) {
            Some(pid) => !process_alive(pid),
            None => depth > 0 && has_dead_temp_files(&dir.join(entry), depth - 1),
        })
}

/// Removes the `scene::atomic` temporary files of dead processes in `dir` and, `depth` levels
/// down, in its subfolders (never through a link). Returns them.
pub fn remove_dead_temp_files(dir: &Path, depth: u32) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    for entry in list(dir).unwrap_or_default() {
        let path = dir.join(&entry);
        if let Some(pid) = temp_file_pid(&entry) {
            if !process_alive(pid) && fs::remove_file(&path).is_ok() {
                removed.push(path);
            }
        } else if depth > 0 && fs::symlink_metadata(&path).is_ok_and(|m| m.is_dir()) {
            removed.extend(remove_dead_temp_files(&path, depth - 1));
        }
    }
    removed
}

/// A staging (`false`) or replaced (`true`) folder's target name and process id.
fn leftover(entry: &str) -> Option<(&str, u32, bool)> {
    let rest = entry.strip_prefix('.')?;
    let (name, pid, is_old) = if let Some((name, pid)) = rest.rsplit_once(STAGING_TAG) {
        (name, pid, false)
    } else {
        let (name, pid) = rest.rsplit_once(OLD_TAG)?;
        (name, pid, true)
    };
    Some((name, pid.parse().ok()?, is_old))
}

/// The process id in a `scene::atomic` temporary name (`.<name>.<pid>.<n>.tmp`).
pub fn temp_file_pid(entry: &str) -> Option<u32> {
    let stem = entry.strip_prefix('.')?.strip_suffix(".tmp")?;
    let mut parts = stem.rsplitn(3, '.');
    let _unique = parts.next()?.parse::<u64>().ok()?;
    parts.next()?.parse().ok()
}

/// Whether process `pid` still runs (this one always does). Where that cannot be checked
/// cheaply, only this process counts as running.
pub fn process_alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    #[cfg(target_os = "linux")]
    {
        Path::new("/proc").join(pid.to_string()).exists()
    }
    #[cfg(not(target_os = "linux"))]
    {
        // Without a cheap liveness check, only leftovers of this process count as live.
        false
    }
}

fn list(dir: &Path) -> io::Result<Vec<String>> {
    let mut names = Vec::new();
    for entry in fs::read_dir(dir)? {
        names.push(entry?.file_name().to_string_lossy().into_owned());
    }
    names.sort();
    Ok(names)
}

fn sync_parent(path: &Path) {
    if let Some(parent) = path.parent()
        && let Ok(dir) = fs::File::open(if parent.as_os_str().is_empty() {
            Path::new(".")
        } else {
            parent
        })
    {
        let _ = dir.sync_all();
    }
}

#[cfg(test)]
mod tests;
