//! One writer at a time: `twin.lock` beside `twin.ron`, held with an OS file lock (`flock` on
//! Linux, through std's `File::try_lock`) while a command changes the project. The kernel drops
//! the lock when its holder exits or is killed, so a lock file left behind never blocks; the
//! holder's command, process id and start time are written in it for the message a second writer
//! gets. Only the mechanism: `Twin::commit` and `Twin::save` take it; readers never do.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// The lock file's name inside a project folder.
pub const LOCK_FILE: &str = "twin.lock";

/// How long a writer waits for another by default. The CLI's commands and the long jobs hold the
/// lock only to write their records (well under a second; a joint `add-survey` reads two
/// datasets, a few seconds), so a writer still waiting after this is stuck behind something else.
pub const DEFAULT_LOCK_WAIT: Duration = Duration::from_secs(30);

/// How often a waiting writer tries again.
const RETRY: Duration = Duration::from_millis(50);

/// The most of a lock file read back for a message (a holder writes about 60 bytes).
const MAX_HOLDER_BYTES: u64 = 4096;

/// Who writes a project, as other writers are told, and how long it waits for one of them.
#[derive(Clone, Debug)]
pub struct Writer {
    /// What the user ran, e.g. `twin update`.
    pub command: String,
    pub wait: Duration,
    /// Told once, when another writer holds the project and this one starts to wait.
    pub tell: Option<fn(&str)>,
}

impl Default for Writer {
    fn default() -> Self {
        Writer {
            command: "damage-twin".into(),
            wait: DEFAULT_LOCK_WAIT,
            tell: None,
        }
    }
}

impl Writer {
    pub fn new(command: impl Into<String>) -> Writer {
        Writer {
            command: command.into(),
            ..Writer::default()
        }
    }

    pub fn waiting(self, wait: Duration) -> Writer {
        Writer { wait, ..self }
    }

    pub fn telling(self, tell: fn(&str)) -> Writer {
        Writer {
            tell: Some(tell),
            ..self
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum LockError {
    #[error(
        "{}: project is being updated by {holder}; waited {}; try again when it finishes",
        file.display(),
        seconds(*waited)
    )]
    Held {
        file: PathBuf,
        holder: String,
        waited: Duration,
    },
    #[error("{}: cannot lock the project: {message}", file.display())]
    Io { file: PathBuf, message: String },
}

/// The project held by this process until dropped.
#[derive(Debug)]
pub struct ProjectLock {
    file: File,
    path: PathBuf,
}

impl ProjectLock {
    /// Takes the lock of the project in `dir`, waiting up to `writer.wait` for another writer
    /// (telling `writer.tell` once who that is); then refuses, naming the holder.
    pub fn acquire(dir: &Path, writer: &Writer) -> Result<ProjectLock, LockError> {
        let path = dir.join(LOCK_FILE);
        let io = |e: std::io::Error| LockError::Io {
            file: path.clone(),
            message: e.to_string(),
        };
        let mut file = open_lock_file(&path).map_err(io)?;
        let started = Instant::now();
        let mut told = false;
        loop {
            match file.try_lock() {
                Ok(()) => break,
                Err(TryLockError::WouldBlock) => {
                    let holder = read_holder(&mut file);
                    let waited = started.elapsed();
                    if waited >= writer.wait {
                        return Err(LockError::Held {
                            file: path,
                            holder,
                            waited,
                        });
                    }
                    if !told && let Some(tell) = writer.tell {
                        tell(&format!(
                            "{}: project is being updated by {holder}; waiting up to {}",
                            path.display(),
                            seconds(writer.wait)
                        ));
                    }
                    told = true;
                    std::thread::sleep(RETRY.min(writer.wait - waited));
                }
                // A file system without locks: the writer's check that `twin.ron` did not change
                // since it was read (`Twin::save`) still refuses to overwrite another's record,
                // only a race inside that check is left open.
                Err(TryLockError::Error(e)) if e.kind() == std::io::ErrorKind::Unsupported => {
                    if let Some(tell) = writer.tell {
                        tell(&format!(
                            "{}: this file system cannot lock files; writing without a lock",
                            path.display()
                        ));
                    }
                    break;
                }
                Err(TryLockError::Error(e)) => return Err(io(e)),
            }
        }
        let since = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        let text = format!(
            "command: {}\npid: {}\nsince: {since}\n",
            writer.command.replace('\n', " "),
            std::process::id()
        );
        file.set_len(0)
            .and_then(|()| file.seek(SeekFrom::Start(0)))
            .and_then(|_| file.write_all(text.as_bytes()))
            .map_err(io)?;
        Ok(ProjectLock { file, path })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for ProjectLock {
    fn drop(&mut self) {
        // Emptied while still held, so that a holder's name outlives it only when it was killed;
        // closing the file releases the lock.
        let _ = self.file.set_len(0);
    }
}

/// Opens (creating) the lock file without truncating it (its holder's name is in it) and without
/// following a symbolic link out of the project; anything but a regular file is refused.
fn open_lock_file(path: &Path) -> std::io::Result<File> {
    let mut options = OpenOptions::new();
    options.read(true).write(true).create(true).truncate(false);
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NOFOLLOW);
    }
    let file = options.open(path)?;
    if !file.metadata()?.is_file() {
        return Err(std::io::Error::other("not a regular file"));
    }
    Ok(file)
}

/// Who holds the lock, from its file: "`twin update` (pid 123) since 10:42 UTC", or "another
/// process" while the holder has not written its name yet (or wrote something else).
fn read_holder(file: &mut File) -> String {
    let mut text = String::new();
    let read = file
        .seek(SeekFrom::Start(0))
        .and_then(|_| file.take(MAX_HOLDER_BYTES).read_to_string(&mut text));
    match (read, parse_holder(&text)) {
        (Ok(_), Some(holder)) => holder.to_string(),
        _ => "another process".into(),
    }
}

/// A lock holder as its file names it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Holder {
    pub command: String,
    pub pid: u32,
    /// Unix seconds when it took the lock.
    pub since: Option<u64>,
}

impl std::fmt::Display for Holder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "`{}` (pid {})", self.command, self.pid)?;
        match self.since {
            Some(since) => write!(f, " since {}", utc_time(since)),
            None => Ok(()),
        }
    }
}

/// The holder a lock file's text names, if it names one.
fn parse_holder(text: &str) -> Option<Holder> {
    let field = |key: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(key)?.strip_prefix(": "))
            .map(str::trim)
    };
    Some(Holder {
        command: field("command")?.to_string(),
        pid: field("pid")?.parse().ok()?,
        since: field("since").and_then(|s| s.parse().ok()),
    })
}

/// Who is writing the project in `dir` now, for a view that only reads it (the app): the holder
/// the lock file names while that process is alive, without taking or probing the lock (a probe
/// would hold it for an instant and could turn a writer away). A holder empties the file when it
/// lets go, so a name left there is a killed holder's, and its process is gone. None for this
/// process's own lock, for no lock file, and off Linux where liveness is not checked.
pub fn current_holder(dir: &Path) -> Option<Holder> {
    let path = dir.join(LOCK_FILE);
    let text = crate::scene::files::read_text(&path, MAX_HOLDER_BYTES).ok()?;
    let holder = parse_holder(&text)?;
    let alive =
        cfg!(target_os = "linux") && Path::new("/proc").join(holder.pid.to_string()).exists();
    (alive && holder.pid != std::process::id()).then_some(holder)
}

/// A wait as the user reads it: `0.3 s`, `30 s`.
fn seconds(wait: Duration) -> String {
    let s = wait.as_secs_f64();
    if s < 10.0 {
        format!("{s:.1} s")
    } else {
        format!("{s:.0} s")
    }
}

/// `HH:MM UTC` of a Unix time, with the date when it is not today's.
fn utc_time(unix_s: u64) -> String {
    let day = unix_s / 86_400;
    let (hours, minutes) = (unix_s % 86_400 / 3600, unix_s % 3600 / 60);
    let today = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() / 86_400);
    let date = if day == today {
        String::new()
    } else {
        format!("{} ", crate::timeline::twin::civil_date(day as i64))
    };
    format!("{date}{hours:02}:{minutes:02} UTC")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_waits_then_names_the_holder() {
        let dir = tempfile::tempdir().unwrap();
        let held = ProjectLock::acquire(dir.path(), &Writer::new("twin update")).unwrap();
        let quick = Writer::new("twin set-scale").waiting(Duration::from_millis(200));
        let started = Instant::now();
        let error = ProjectLock::acquire(dir.path(), &quick)
            .unwrap_err()
            .to_string();
        assert!(started.elapsed() >= Duration::from_millis(200));
        let pid = format!("`twin update` (pid {}) since ", std::process::id());
        assert!(
            error.contains(LOCK_FILE) && error.contains(&pid) && error.contains(" UTC"),
            "{error}"
        );
        drop(held);
        // Released: the next writer takes it at once.
        let again = ProjectLock::acquire(dir.path(), &quick.waiting(Duration::ZERO)).unwrap();
        assert_eq!(again.path(), dir.path().join(LOCK_FILE));
    }

    #[test]
    fn holder_text_that_is_not_a_holder_reads_as_another_process() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(LOCK_FILE);
        std::fs::write(&path, "\u{0}garbage").unwrap();
        let mut file = File::open(&path).unwrap();
        assert_eq!(read_holder(&mut file), "another process");
        assert_eq!(utc_time(0), "1970-01-01 00:00 UTC");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_lock_file_that_links_out_of_the_project_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let outside = dir.path().join("outside");
        std::fs::write(&outside, "keep").unwrap();
        let project = dir.path().join("project");
        std::fs::create_dir(&project).unwrap();
        std::os::unix::fs::symlink(&outside, project.join(LOCK_FILE)).unwrap();
        let error = ProjectLock::acquire(&project, &Writer::default()).unwrap_err();
        assert!(matches!(error, LockError::Io { .. }), "{error}");
        assert_eq!(std::fs::read_to_string(&outside).unwrap(), "keep");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_reader_sees_a_live_holder_not_its_own_lock_nor_a_killed_ones() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(current_holder(dir.path()), None, "no lock file");
        let held = ProjectLock::acquire(dir.path(), &Writer::new("twin update")).unwrap();
        assert_eq!(current_holder(dir.path()), None, "this process's own lock");
        drop(held);
        assert_eq!(
            current_holder(dir.path()),
            None,
            "let go: the file is emptied"
        );
        let path = dir.path().join(LOCK_FILE);
        // Process 1 is always alive: another writer holding the project since 00:00 UTC.
        std::fs::write(&path, "command: twin detect\npid: 1\nsince: 0\n").unwrap();
        let holder = current_holder(dir.path()).expect("a live holder");
        assert_eq!(
            holder.to_string(),
            "`twin detect` (pid 1) since 1970-01-01 00:00 UTC"
        );
        // No process has this id (pid_max is at most 2^22): a killed holder's name.
        std::fs::write(&path, "command: twin update\npid: 4294967294\n").unwrap();
        assert_eq!(current_holder(dir.path()), None);
    }
}
