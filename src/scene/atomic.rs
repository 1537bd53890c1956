//! Atomic file replacement: write a temporary file beside the target, fsync it, rename it over
//! the target, fsync the folder. A crash leaves either the old file or the new one, never half.
//! Only the mechanism; callers choose the bytes.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::scene::SceneError;

static COUNTER: AtomicU64 = AtomicU64::new(0);

fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "file".into());
    let unique = COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.{}.{unique}.tmp", std::process::id()))
}

/// Writes `path` atomically with `write`. On any error the temporary file is removed and the
/// old `path` (if any) is untouched.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<(), SceneError> {
    write_pending(path, write)?.commit()
}

/// A new version of a file written and synced beside it under a temporary name, not yet in its
/// place: `commit` renames it there. Dropped uncommitted, it is removed. A process killed in
/// between leaves the temporary file, named with its process id (`.<name>.<pid>.<n>.tmp`), for
/// whoever cleans up after it (`scene::run_folder::temp_file_pid`).
#[derive(Debug)]
pub struct PendingFile {
    temp: PathBuf,
    path: PathBuf,
    committed: bool,
}

/// The first half of `write_atomic`: the bytes written and synced under a temporary name.
pub fn write_pending(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<PendingFile, SceneError> {
    let temp = temp_path(path);
    let result = (|| -> std::io::Result<()> {
        let file = File::create(&temp)?;
        let mut writer = BufWriter::with_capacity(1 << 16, file);
        write(&mut writer)?;
        writer.flush()?;
        let file = writer.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()
    })();
    match result {
        Ok(()) => Ok(PendingFile {
            temp,
            path: path.to_path_buf(),
            committed: false,
        }),
        Err(e) => {
            let _ = std::fs::remove_file(&temp);
            Err(SceneError::io(path, e))
        }
    }
}

impl PendingFile {
    /// Puts the file in its place (one rename) and syncs the folder.
    pub fn commit(mut self) -> Result<(), SceneError> {
        std::fs::rename(&self.temp, &self.path).map_err(|e| SceneError::io(&self.path, e))?;
        self.committed = true;
        sync_parent(&self.path);
        Ok(())
    }
}

impl Drop for PendingFile {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_file(&self.temp);
        }
    }
}

/// fsyncs the folder holding `path` so the rename itself is durable. Best effort: some
/// platforms/filesystems cannot open or sync a directory, and the data is already synced.
fn sync_parent(path: &Path) {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if let Ok(dir) = File::open(parent) {
        let _ = dir.sync_all();
    }
}
