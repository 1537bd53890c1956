//! Running COLMAP: where the program is, one command at a time with its output appended to the
//! dataset's log and read for progress, and a failure reported with the command and the last
//! lines COLMAP printed.

use std::collections::VecDeque;
use std::ffi::OsString;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::scene::SceneError;
use crate::scene::sfm::SfmError;
use crate::scene::sfm::progress::{Progress, parse_line};

/// Names COLMAP's program when it is not `colmap` on PATH.
pub const COLMAP_ENV: &str = "DAMAGE_TWIN_COLMAP";

/// Lines of COLMAP's output quoted in a failure.
const TAIL_LINES: usize = 6;

/// The COLMAP program to run.
#[derive(Clone, Debug)]
pub struct Colmap {
    program: PathBuf,
}

impl Colmap {
    /// `$DAMAGE_TWIN_COLMAP`, else `colmap` found on PATH; the error names the package.
    pub fn find() -> Result<Colmap, SfmError> {
        if let Some(program) = std::env::var_os(COLMAP_ENV).filter(|p| !p.is_empty()) {
            let program = PathBuf::from(program);
            return if is_executable(&program) {
                Ok(Colmap { program })
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
            .map(|program| Colmap { program })
            .ok_or_else(|| SfmError::EngineMissing {
                program: "colmap".into(),
            })
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
    /// A non-zero exit (or a signal) is `EngineFailed` with the command and the last lines.
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
        for line in lines {
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
