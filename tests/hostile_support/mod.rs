//! Shared by the hostile-input tests (`hostile_inputs` for datasets and models,
//! `hostile_projects` for twin projects): a FIFO, a deadline for a library call, running the
//! binary with a kill after a hang, and the check that a refusal is one prompt error line.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use tempfile::TempDir;

/// A command that takes longer than this is a hang. The refusals below take well under a second
/// in the dev profile; 10 s leaves room for a busy two-core machine.
pub const PROMPT: Duration = Duration::from_secs(10);

/// Where the child is killed and the test fails: three times `PROMPT`.
pub const HANG: Duration = Duration::from_secs(30);

/// A `transforms.json` dataset of three 8 × 8 frames and no points (random initialisation).
pub fn transforms_dataset() -> TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    std::fs::create_dir_all(root.join("images")).unwrap();
    let mut frames = Vec::new();
    for i in 0..3 {
        image::RgbImage::from_pixel(8, 8, image::Rgb([40 * i as u8, 90, 150]))
            .save(root.join(format!("images/f{i}.png")))
            .unwrap();
        frames.push(format!(
            r#"{{"file_path":"images/f{i}.png","transform_matrix":[[1,0,0,{x}],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}}"#,
            x = 0.1 * i as f64
        ));
    }
    std::fs::write(
        root.join("transforms.json"),
        format!(
            r#"{{"fl_x":8,"w":8,"h":8,"frames":[{}]}}"#,
            frames.join(",")
        ),
    )
    .unwrap();
    tmp
}

#[cfg(target_os = "linux")]
pub fn fifo(path: &Path) -> PathBuf {
    let c_path = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
    // SAFETY: `c_path` is a valid NUL-terminated path that outlives the call.
    assert_eq!(unsafe { libc::mkfifo(c_path.as_ptr(), 0o600) }, 0);
    path.to_path_buf()
}

/// Runs `f` on a thread and fails the test if it does not return within `PROMPT` (a regression
/// that blocks in `open` must fail, not hang the suite).
pub fn promptly<T: Send + 'static>(what: &str, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(PROMPT)
        .unwrap_or_else(|_| panic!("{what}: no answer within {PROMPT:?}"))
}

/// The outcome of one CLI run.
pub struct Run {
    pub code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
    pub seconds: f64,
}

/// Runs the binary with `args`, killing it after `HANG`.
pub fn cli(args: &[OsString]) -> Run {
    let start = Instant::now();
    // `DAMAGE_TWIN_TEST_BIN` runs another build, to see a test fail against the code before a fix.
    let binary = std::env::var_os("DAMAGE_TWIN_TEST_BIN")
        .unwrap_or_else(|| env!("CARGO_BIN_EXE_damage-twin").into());
    let mut child = Command::new(binary)
        .args(args)
        .env("RAYON_NUM_THREADS", "2")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if start.elapsed() > HANG {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?}: still running after {HANG:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    Run {
        code: out.status.code(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        seconds: start.elapsed().as_secs_f64(),
    }
}

pub fn args(parts: &[&dyn AsRef<std::ffi::OsStr>]) -> Vec<OsString> {
    parts.iter().map(|p| p.as_ref().to_os_string()).collect()
}

/// The command failed promptly with exit status 1 or 2 and one error line (warnings aside)
/// holding every needle, and nothing panicked.
pub fn refused(run: &Run, needles: &[&str]) {
    assert!(
        matches!(run.code, Some(1) | Some(2)),
        "exit {:?}\nstdout: {}\nstderr: {}",
        run.code,
        run.stdout,
        run.stderr
    );
    assert!(!run.stderr.contains("panicked"), "{}", run.stderr);
    assert!(run.seconds < PROMPT.as_secs_f64(), "took {} s", run.seconds);
    // clap's usage errors add a usage block after a blank line; the error itself is one line.
    // Progress lines before it (`report`'s per-survey lines) are not part of it.
    let lines: Vec<&str> = run
        .stderr
        .lines()
        .filter(|l| !l.starts_with("warning:"))
        .skip_while(|l| !l.starts_with("error"))
        .take_while(|l| !l.trim().is_empty())
        .collect();
    assert_eq!(lines.len(), 1, "not one error line: {}", run.stderr);
    for needle in needles {
        assert!(lines[0].contains(needle), "{needle:?} not in: {}", lines[0]);
    }
}
