//! Running COLMAP: which engine and where its program is, one command at a time with its output
//! appended to the dataset's log and read for progress, and a failure reported with the command
//! and the last lines COLMAP printed.
//!
//! Two engines take the same commands and options (`feature_extractor --database_path …`):
//! COLMAP's command-line program (Debian's `colmap` 3.8), and COLMAP 4 through the `pycolmap`
//! wheel, driven by `scripts/pycolmap_engine.py` (shipped inside the binary and written into the
//! dataset's `colmap/` folder, so a dataset names the exact script that made it). Which is the
//! default was chosen by measurement on lund (docs/POSE.md).

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

/// Names COLMAP's program when it is not `colmap` on PATH; set, it also makes the CLI engine the
/// default (a program named by hand is the one meant).
pub const COLMAP_ENV: &str = "DAMAGE_TWIN_COLMAP";
/// Names the Python that has `pycolmap` when it is not `python3` on PATH.
pub const PYTHON_ENV: &str = "DAMAGE_TWIN_PYTHON";
/// The script driving COLMAP 4 through pycolmap, as shipped in the repository.
const PYCOLMAP_SCRIPT: &str = include_str!("../../../scripts/pycolmap_engine.py");
/// Its name in the dataset's COLMAP workspace.
pub const PYCOLMAP_SCRIPT_FILE: &str = "pycolmap_engine.py";

/// The structure-from-motion engine: both run COLMAP, with the same command names and options.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Engine {
    /// COLMAP's command-line program: `colmap` on PATH or `$DAMAGE_TWIN_COLMAP`.
    Colmap,
    /// COLMAP 4 through `pycolmap` (`pip install pycolmap`), run by `python3` (or
    /// `$DAMAGE_TWIN_PYTHON`) with the shipped `pycolmap_engine.py`.
    Pycolmap,
}

impl Engine {
    /// The engine measured best on lund (docs/POSE.md), unless `$DAMAGE_TWIN_COLMAP` names a
    /// COLMAP program: then that program.
    pub fn default_choice() -> Engine {
        if Engine::colmap_named() {
            Engine::Colmap
        } else {
            MEASURED_DEFAULT
        }
    }

    /// Whether `$DAMAGE_TWIN_COLMAP` names a COLMAP program (then it is the engine meant).
    pub fn colmap_named() -> bool {
        std::env::var_os(COLMAP_ENV).is_some_and(|p| !p.is_empty())
    }

    pub fn name(self) -> &'static str {
        match self {
            Engine::Colmap => "colmap",
            Engine::Pycolmap => "pycolmap",
        }
    }

    /// `colmap` or `pycolmap`, as the command line and the app spell them.
    pub fn parse(text: &str) -> Option<Engine> {
        match text {
            "colmap" => Some(Engine::Colmap),
            "pycolmap" => Some(Engine::Pycolmap),
            _ => None,
        }
    }
}

/// The default engine, chosen by the lund measurements in docs/POSE.md: COLMAP 4 through
/// pycolmap registered 28 of 29 photos within tolerance (27 of 27 of the shipped model) in 77 s
/// of CPU, where Debian's 3.8 registered all, two components or none in three runs of the
/// same settings and spent minutes matching.
const MEASURED_DEFAULT: Engine = Engine::Pycolmap;

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
    /// Arguments before the COLMAP command: the script's path for the pycolmap engine.
    leading: Vec<OsString>,
    engine: Engine,
}

impl Colmap {
    /// `engine`'s program, checked before anything is written: the error names what to install.
    /// The pycolmap engine still needs `prepare` (its script written into the workspace).
    pub fn for_engine(engine: Engine) -> Result<Colmap, SfmError> {
        match engine {
            Engine::Colmap => Colmap::find(),
            Engine::Pycolmap => find_pycolmap(),
        }
    }

    pub fn engine(&self) -> Engine {
        self.engine
    }

    /// Makes the engine ready to run in the COLMAP workspace `work`: the pycolmap engine's script
    /// is written there (and run from there); the CLI needs nothing.
    pub fn prepare(&mut self, work: &Path) -> Result<(), SfmError> {
        if self.engine == Engine::Pycolmap {
            let script = work.join(PYCOLMAP_SCRIPT_FILE);
            std::fs::write(&script, PYCOLMAP_SCRIPT).map_err(|e| SceneError::io(&script, e))?;
            self.leading = vec![script.into_os_string()];
        }
        Ok(())
    }

    /// `$DAMAGE_TWIN_COLMAP`, else `colmap` found on PATH; the error names the package.
    pub fn find() -> Result<Colmap, SfmError> {
        if let Some(program) = std::env::var_os(COLMAP_ENV).filter(|p| !p.is_empty()) {
            let program = PathBuf::from(program);
            return if is_executable(&program) {
                Ok(Colmap::cli(program))
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
            .map(Colmap::cli)
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

    fn cli(program: PathBuf) -> Colmap {
        Colmap {
            program,
            cancel: None,
            leading: Vec::new(),
            engine: Engine::Colmap,
        }
    }

    pub fn program(&self) -> &Path {
        &self.program
    }

    /// COLMAP's own first line of `colmap help` ("COLMAP 3.8 -- Structure-from-Motion…"), or
    /// "unknown" when it prints none.
    pub fn version(&self) -> String {
        let output = Command::new(&self.program)
            .args(&self.leading)
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
            .chain(
                self.leading
                    .iter()
                    .map(|a| a.to_string_lossy().into_owned()),
            )
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
            .args(&self.leading)
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

/// `python3` (or `$DAMAGE_TWIN_PYTHON`) that imports `pycolmap`, else the error saying what is
/// missing and what to install.
fn find_pycolmap() -> Result<Colmap, SfmError> {
    let python = match std::env::var_os(PYTHON_ENV).filter(|p| !p.is_empty()) {
        Some(p) => Some(PathBuf::from(p)).filter(|p| is_executable(p)),
        None => {
            let path = std::env::var_os("PATH").unwrap_or_default();
            std::env::split_paths(&path)
                .map(|dir| dir.join("python3"))
                .find(|p| is_executable(p))
        }
    };
    let Some(python) = python else {
        let named = std::env::var_os(PYTHON_ENV)
            .filter(|p| !p.is_empty())
            .map_or("python3 was not found on PATH".to_owned(), |p| {
                format!("{PYTHON_ENV}={} is not an executable", p.to_string_lossy())
            });
        return Err(SfmError::PycolmapMissing { why: named });
    };
    let imports = Command::new(&python)
        .args(["-c", "import pycolmap"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !imports {
        return Err(SfmError::PycolmapMissing {
            why: format!("{} cannot import pycolmap", python.display()),
        });
    }
    Ok(Colmap {
        program: python,
        cancel: None,
        leading: Vec::new(),
        engine: Engine::Pycolmap,
    })
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
        let colmap = Colmap::cli(silent_colmap(dir.path())).cancelled_by(Some(cancel.clone()));
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
