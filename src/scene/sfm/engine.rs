//! Running COLMAP: where the program is, one command at a time with its output appended to the
//! dataset's log and read for progress, and a failure reported with the command and the last
//! lines COLMAP printed.

use std::collections::VecDeque;
use std::ffi::OsString;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::scene::SceneError;
use crate::scene::sfm::SfmError;
use crate::scene::sfm::progress::{Progress, parse_line};

/// Names COLMAP's program when it is not `colmap` on PATH.
pub const COLMAP_ENV: &str = "DAMAGE_TWIN_COLMAP";

/// Lines of COLMAP's output quoted in a failure.
const TAIL_LINES: usize = 6;

/// How often a silent COLMAP (the mapper can print nothing for minutes) is checked for a cancel.
const CANCEL_POLL: Duration = Duration::from_millis(100);

/// The COLMAP program to run.
#[derive(Clone, Debug)]
pub struct Colmap {
    program: PathBuf,
    /// Set by another thread to stop the run (`cancelled_by`).
    cancel: Option<Arc<AtomicBool>>,
}

impl Colmap {
    /// `$DAMAGE_TWIN_COLMAP`, else `colmap` found on PATH; the error names the package.
    pub fn find() -> Result<Colmap, SfmError> {
        if let Some(program) = std::env::var_os(COLMAP_ENV).filter(|p| !p.is_empty()) {
            let program = PathBuf::from(program);
            return if is_executable(&program) {
                Ok(Colmap {
                    program,
                    cancel: None,
                })
            } else {
                Err(SfmError::EngineMissing {
                    program: program.display().to_string(),
                })
            };
        }
        let path = std::env::var_os("PATH").unwrap_or_default();
        std::env::split_paths(&path)
            .map(|dir| dir.join("colmap"))
            .find(|p| is_executable(p))
            .map(|program| Colmap {
                program,
                cancel: None,
            })
            .ok_or_else(|| SfmError::EngineMissing {
                program: "colmap".into(),
            })
    }

    /// The same program, stopped when `cancel` is set (another thread sets it): a running
    /// command is killed and `run` returns `SfmError::Cancelled`, as does every later `run`.
    pub fn cancelled_by(self, cancel: Option<Arc<AtomicBool>>) -> Colmap {
        Colmap { cancel, ..self }
    }

    fn is_cancelled(&self) -> bool {
        self.cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
    }

    pub fn program(&self) -> &Path {
        &self.program
    }

    /// COLMAP's own first line of `colmap help` ("COLMAP 3.8 -- Structure-from-Motion…"), or
    /// "unknown" when it prints none.
    pub fn version(&self) -> String {
        let output = Command::new(&self.program)
            .arg("help")
            .stdin(Stdio::null())
            .output();
        output
            .ok()
            .and_then(|o| {
                String::from_utf8_lossy(&o.stdout)
                    .lines()
                    .map(str::trim)
                    .find(|l| l.starts_with("COLMAP"))
                    .map(str::to_owned)
            })
            .unwrap_or_else(|| "unknown".into())
    }

    /// Runs `colmap <command> <args>`, appending a header and everything it prints to `log`,
    /// and calling `progress` for each line that reports progress (`photos`: the photo count).
    /// A non-zero exit (or a signal) is `EngineFailed` with the command and the last lines; a
    /// cancel kills COLMAP and is `Cancelled`.
    pub fn run(
        &self,
        command: &str,
        args: &[OsString],
        log: &Path,
        photos: usize,
        progress: &dyn Fn(Progress),
    ) -> Result<(), SfmError> {
        let shown = std::iter::once(self.program.display().to_string())
            .chain(std::iter::once(command.to_owned()))
            .chain(args.iter().map(|a| a.to_string_lossy().into_owned()))
            .collect::<Vec<_>>()
            .join(" ");
        if self.is_cancelled() {
            return Err(SfmError::Cancelled);
        }
        let mut log_file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log)
            .map_err(|e| SceneError::io(log, e))?;
        let log_error = |e| SfmError::from(SceneError::io(log, e));
        writeln!(log_file, "\n$ {shown}").map_err(log_error)?;
        let mut child = Command::new(&self.program)
            .arg(command)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| SfmError::EngineFailed {
                command: shown.clone(),
                status: format!("could not start: {e}"),
                tail: String::new(),
                log: log.to_path_buf(),
            })?;
        // Both pipes read at once (one thread each), so neither fills and stalls COLMAP.
        let (sender, lines) = crossbeam_channel::unbounded::<String>();
        let readers: Vec<_> = [
            child
                .stdout
                .take()
                .map(|s| Box::new(s) as Box<dyn Read + Send>),
            child
                .stderr
                .take()
                .map(|s| Box::new(s) as Box<dyn Read + Send>),
        ]
        .into_iter()
        .flatten()
        .map(|pipe| {
            let sender = sender.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(pipe).split(b'\n').map_while(Result::ok) {
                    let line = String::from_utf8_lossy(&line).trim_end().to_owned();
                    if sender.send(line).is_err() {
                        break;
                    }
                }
            })
        })
        .collect();
        drop(sender);
        let mut tail: VecDeque<String> = VecDeque::with_capacity(TAIL_LINES);
        loop {
            let line = match lines.recv_timeout(CANCEL_POLL) {
                Ok(line) => line,
                Err(crossbeam_channel::RecvTimeoutError::Timeout) => {
                    if self.is_cancelled() {
                        let _ = child.kill();
                        let _ = child.wait();
                        // The readers end when the pipes close; a grandchild COLMAP started may
                        // hold them a little longer, so they are not waited for.
                        let _ = writeln!(log_file, "(cancelled: COLMAP was stopped)");
                        return Err(SfmError::Cancelled);
                    }
                    continue;
                }
                Err(crossbeam_channel::RecvTimeoutError::Disconnected) => break,
            };
            writeln!(log_file, "{line}").map_err(log_error)?;
            if let Some(p) = parse_line(&line, photos) {
                progress(p);
            }
            if !line.trim().is_empty() {
                if tail.len() == TAIL_LINES {
                    tail.pop_front();
                }
                tail.push_back(line.trim().to_owned());
            }
        }
        for reader in readers {
            let _ = reader.join();
        }
        let status = child.wait().map_err(|e| SceneError::io(&self.program, e))?;
        log_file.flush().map_err(log_error)?;
        if status.success() {
            return Ok(());
        }
        Err(SfmError::EngineFailed {
            command: shown,
            status: status.to_string(),
            tail: if tail.is_empty() {
                "(none)".into()
            } else {
                Vec::from(tail).join(" | ")
            },
            log: log.to_path_buf(),
        })
    }
}

#[cfg(unix)]
fn is_executable(path: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(path).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

#[cfg(not(unix))]
fn is_executable(path: &Path) -> bool {
    path.is_file()
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    /// A `colmap` that prints one progress line and then waits silently, as the mapper does.
    fn silent_colmap(dir: &Path) -> PathBuf {
        use std::os::unix::fs::PermissionsExt;
        let path = dir.join("colmap");
        std::fs::write(
            &path,
            "#!/bin/sh\necho 'Processed file [1/2]'\nexec sleep 30\n",
        )
        .unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
        path
    }

    #[test]
    fn a_cancel_stops_a_silent_colmap_at_once() {
        let dir = tempfile::tempdir().unwrap();
        let cancel = Arc::new(AtomicBool::new(false));
        let colmap = Colmap {
            program: silent_colmap(dir.path()),
            cancel: None,
        }
        .cancelled_by(Some(cancel.clone()));
        let log = dir.path().join("colmap.log");
        let setter = {
            let cancel = cancel.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(300));
                cancel.store(true, Ordering::Relaxed);
            })
        };
        let started = std::time::Instant::now();
        let seen = std::sync::Mutex::new(Vec::new());
        let result = colmap.run("mapper", &[], &log, 2, &|p| seen.lock().unwrap().push(p));
        setter.join().unwrap();
        assert!(matches!(result, Err(SfmError::Cancelled)), "{result:?}");
        assert!(
            started.elapsed() < Duration::from_secs(5),
            "took {:?}",
            started.elapsed()
        );
        assert_eq!(
            seen.lock().unwrap().len(),
            1,
            "the progress before the cancel"
        );
        // Once cancelled, nothing more is started.
        let again = colmap.run("mapper", &[], &log, 2, &|_| {});
        assert!(matches!(again, Err(SfmError::Cancelled)), "{again:?}");
    }
}
