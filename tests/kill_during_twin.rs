//! kill -9 during `twin add-survey`, `twin update`, `twin detect` and `report` (issue 45 §4): after
//! every kill the project opens, the earlier survey's model keeps its bytes, the survey the
//! killed command wrote is its previous state or its new one whole (model, metrics, history and
//! the light recorded in `twin.ron` in step), and the next command removes every staging folder
//! and temporary file the killed one left, saying so.
//!
//! Two kinds of kill: aborts injected at each point of the commit (`DAMAGE_TWIN_ABORT_AT`,
//! `timeline::twin::staging`), and SIGKILLs at random moments of a run. `DAMAGE_TWIN_KILLS=N`
//! sets the random kills per command (default 3, seconds; the nightly-style run uses 30).
//! Self-contained: a tiny synthetic building, no shared data.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use damage_twin::timeline::Twin;

const KILLS_ENV: &str = "DAMAGE_TWIN_KILLS";

fn binary() -> Command {
    Command::new(env!("CARGO_BIN_EXE_damage-twin"))
}

fn run(mut command: Command) -> Output {
    let output = command.output().expect("runs");
    assert!(
        output.status.success(),
        "{command:?} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

struct Fixture {
    root: tempfile::TempDir,
}

impl Fixture {
    /// A project with survey s1 (trained briefly), s2 added, updated and detected.
    fn new() -> Fixture {
        let root = tempfile::tempdir().unwrap();
        let params = damage_twin::synth::SynthParams {
            width: 96,
            height: 54,
            views: 8,
            views_survey2: 6,
            surveys: 2,
            sparse_points: 1500,
            ..damage_twin::synth::SynthParams::demo(root.path().join("synth"))
        };
        damage_twin::synth::generate(&params, &|_, _| {}).expect("synth");
        let fixture = Fixture { root };
        let synth = fixture.root.path().join("synth");
        let mut new = fixture.twin(&["new"]);
        new.args(["--survey", "s1", "--date", "2024-01-01", "--iters", "20"])
            .arg("--dataset")
            .arg(synth.join("survey-1"))
            .arg("--quiet");
        run(new);
        let mut add = fixture.twin(&["add-survey"]);
        add.args(["--survey", "s2", "--date", "2025-01-01", "--dataset"])
            .arg(synth.join("survey-2"));
        run(add);
        run(fixture.update(3));
        run(fixture.detect());
        fixture
    }

    fn project(&self) -> PathBuf {
        self.root.path().join("project")
    }

    fn report_dir(&self) -> PathBuf {
        self.root.path().join("report")
    }

    fn twin(&self, args: &[&str]) -> Command {
        let mut command = binary();
        command.arg("twin").args(args).arg(self.project());
        command.stdout(Stdio::null()).stderr(Stdio::piped());
        command
    }

    /// An update of s2 for `iters` steps: runs of other step counts write other files, so the
    /// step count tells which run a file is from.
    fn update(&self, iters: u32) -> Command {
        let mut command = self.twin(&["update"]);
        command.args(["--survey", "s2", "--quiet", "--iters"]);
        command.arg(iters.to_string());
        command
    }

    fn detect(&self) -> Command {
        let mut command = self.twin(&["detect"]);
        command.args(["--survey", "s2"]);
        command
    }

    fn add_survey(&self, name: &str) -> Command {
        let mut command = self.twin(&["add-survey"]);
        command
            .args(["--survey", name, "--date", "2025-01-02", "--dataset"])
            .arg(self.root.path().join("synth/survey-2"));
        command
    }

    fn report(&self) -> Command {
        let mut command = binary();
        command
            .arg("report")
            .arg(self.project())
            .arg("--out")
            .arg(self.report_dir())
            .args(["--views", "1", "--downscale", "4"]);
        command.stdout(Stdio::null()).stderr(Stdio::piped());
        command
    }

    fn file(&self, relative: &str) -> Vec<u8> {
        std::fs::read(self.project().join(relative)).unwrap_or_default()
    }
}

/// Every staging, replaced or temporary entry under `dir`.
fn leftovers(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            let path = entry.path();
            if name.contains(".staging-") || name.contains(".replaced-") || name.ends_with(".tmp") {
                found.push(path.clone());
            }
            if path.is_dir() {
                stack.push(path);
            }
        }
    }
    found
}

/// Survey s2's update as the project holds it, checked to be one run's: its model, its
/// `metrics.json`, its `history.json` and the light `twin.ron` records for it agree. Returns the
/// run's step count.
fn update_state(fixture: &Fixture, when: &str) -> u64 {
    let twin = Twin::open(&fixture.project()).unwrap_or_else(|e| panic!("{when}: {e}"));
    let recorded = twin.survey("s2").unwrap().appearance;
    let json = |file: &str| -> serde_json::Value {
        serde_json::from_slice(&fixture.file(&format!("surveys/s2/{file}")))
            .unwrap_or_else(|e| panic!("{when}: {file}: {e}"))
    };
    let (metrics, history) = (json("metrics.json"), json("history.json"));
    let in_metrics: Option<damage_twin::scene::project::ColourTransform> =
        serde_json::from_value(metrics["appearance"].clone()).unwrap();
    assert_eq!(
        recorded, in_metrics,
        "{when}: twin.ron's light of s2 is not the one its metrics.json was written with"
    );
    let model =
        damage_twin::splats::ply::read_splats(&fixture.project().join("surveys/s2/model.ply"))
            .unwrap_or_else(|e| panic!("{when}: model.ply: {e}"));
    assert_eq!(
        metrics["refine"]["gaussians_after"].as_u64(),
        Some(model.len() as u64),
        "{when}: model.ply is not the model metrics.json describes"
    );
    let iterations = metrics["refine"]["iterations"].as_u64().unwrap();
    let samples = history["samples"].as_array().unwrap();
    assert_eq!(
        samples.last().and_then(|s| s["step"].as_u64()),
        Some(iterations),
        "{when}: history.json is another run's than metrics.json"
    );
    iterations
}

/// What every kill must leave: the project opens after the next command, which cleaned up (and
/// said so when there was something to clean), and the earlier survey's model is untouched.
fn next_command_cleans(fixture: &Fixture, s1_model: &[u8], when: &str) {
    let left = leftovers(&fixture.project());
    let status = run(fixture.twin(&["status"]));
    let said = String::from_utf8_lossy(&status.stderr).into_owned();
    if !left.is_empty() {
        assert!(
            said.contains("cleaned up after a command that was killed"),
            "{when}: {left:?} cleaned silently: {said}"
        );
    }
    let left = leftovers(&fixture.project());
    assert!(
        left.is_empty(),
        "{when}: left after the next command: {left:?}"
    );
    assert_eq!(
        fixture.file("surveys/s1/model.ply"),
        s1_model,
        "{when}: the earlier survey's model changed"
    );
}

fn kills() -> usize {
    std::env::var(KILLS_ENV)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3)
}

/// Starts `command`, kills it (SIGKILL) after `delay` unless it ended first. True when killed.
fn kill_after(mut command: Command, delay: Duration) -> bool {
    let mut child = command.stderr(Stdio::null()).spawn().expect("starts");
    let started = Instant::now();
    while started.elapsed() < delay {
        if child.try_wait().unwrap().is_some() {
            return false;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().expect("kills");
    child.wait().unwrap();
    true
}

fn timed(command: Command) -> Duration {
    let started = Instant::now();
    run(command);
    started.elapsed()
}

#[test]
fn an_abort_at_each_point_of_a_commit_leaves_the_old_or_the_new_survey() {
    let fixture = Fixture::new();
    let s1_model = fixture.file("surveys/s1/model.ply");
    // Before the project file's rename: rolled back. After it: committed.
    let points = [
        ("carrying", false),
        ("between-renames", false),
        ("project-staged", false),
        ("folders-installed", false),
        ("project-renamed", true),
    ];
    for (i, (point, committed)) in points.into_iter().enumerate() {
        let before = update_state(&fixture, point);
        let iters = 4 + i as u32 % 2;
        let mut update = fixture.update(iters);
        update.env("DAMAGE_TWIN_ABORT_AT", point);
        let status = update.status().unwrap();
        assert!(!status.success(), "{point}: the abort did not happen");
        next_command_cleans(&fixture, &s1_model, point);
        let after = update_state(&fixture, point);
        let expected = if committed { u64::from(iters) } else { before };
        assert_eq!(after, expected, "{point}: committed {committed} expected");
    }
    // A detection aborted before its commit point keeps the previous change maps.
    let maps = fixture.project().join("surveys/s2/changes");
    std::fs::write(maps.join("view-000.png"), b"the previous map").unwrap();
    let mut detect = fixture.detect();
    detect.env("DAMAGE_TWIN_ABORT_AT", "folders-installed");
    assert!(!detect.status().unwrap().success());
    next_command_cleans(&fixture, &s1_model, "detect");
    assert_eq!(
        std::fs::read(maps.join("view-000.png")).unwrap(),
        b"the previous map"
    );
}

#[test]
fn random_kills_of_every_writing_command_lose_nothing() {
    let fixture = Fixture::new();
    let s1_model = fixture.file("surveys/s1/model.ply");
    let kills = kills();
    let mut rng = fastrand::Rng::with_seed(45);
    let mut figures = BTreeMap::new();
    let started = Instant::now();

    // `twin update`: s2's files and record are the previous update's or the new one's, whole.
    let full = timed(fixture.update(3));
    let mut killed = 0;
    for k in 0..kills {
        let when = format!("update kill {k}");
        let before = update_state(&fixture, &when);
        let iters = 4 + k as u32 % 2;
        let delay = full.mul_f64(rng.f64() * 1.1);
        killed += usize::from(kill_after(fixture.update(iters), delay));
        next_command_cleans(&fixture, &s1_model, &when);
        let after = update_state(&fixture, &when);
        assert!(
            after == before || after == u64::from(iters),
            "{when}: s2 is neither the previous update ({before} steps) nor the new one ({iters})"
        );
    }
    figures.insert("twin update", (kills, killed, full));

    // `twin detect`: the change maps are the previous detection's or the new one's, all of them.
    let full = timed(fixture.detect());
    let mut killed = 0;
    for k in 0..kills {
        let when = format!("detect kill {k}");
        killed += usize::from(kill_after(fixture.detect(), full.mul_f64(rng.f64() * 1.1)));
        next_command_cleans(&fixture, &s1_model, &when);
        let maps = fixture.project().join("surveys/s2/changes");
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(maps.join("changes.json")).unwrap()).unwrap();
        let pngs = std::fs::read_dir(&maps)
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .path()
                    .extension()
                    .is_some_and(|x| x == "png")
            })
            .count();
        assert_eq!(Some(pngs as u64), summary["views"].as_u64(), "{when}");
        update_state(&fixture, &when);
    }
    figures.insert("twin detect", (kills, killed, full));

    // `twin add-survey`: the survey is there or not; every earlier survey stays.
    let full = timed(fixture.add_survey("timing"));
    let mut killed = 0;
    for k in 0..kills {
        let when = format!("add-survey kill {k}");
        let name = format!("added-{k}");
        let delay = full.mul_f64(rng.f64() * 1.1);
        killed += usize::from(kill_after(fixture.add_survey(&name), delay));
        next_command_cleans(&fixture, &s1_model, &when);
        let twin = Twin::open(&fixture.project()).unwrap();
        assert!(
            twin.survey("s1").is_ok() && twin.survey("s2").is_ok(),
            "{when}"
        );
        update_state(&fixture, &when);
    }
    figures.insert("twin add-survey", (kills, killed, full));

    // `report`: the project is only read; the next report removes what a killed one left.
    let full = timed(fixture.report());
    let mut killed = 0;
    for k in 0..kills {
        let when = format!("report kill {k}");
        killed += usize::from(kill_after(fixture.report(), full.mul_f64(rng.f64() * 1.1)));
        next_command_cleans(&fixture, &s1_model, &when);
        run(fixture.report());
        let left = leftovers(&fixture.report_dir());
        assert!(left.is_empty(), "{when}: {left:?}");
        update_state(&fixture, &when);
    }
    figures.insert("report", (kills, killed, full));

    for (command, (runs, killed, full)) in &figures {
        eprintln!(
            "{command}: {runs} runs, {killed} killed before the end (a run takes {:.2} s)",
            full.as_secs_f64()
        );
    }
    eprintln!(
        "all kills in {:.0} s, no failure",
        started.elapsed().as_secs_f64()
    );
}
