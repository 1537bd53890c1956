//! A seeded fuzz harness for every scene reader, on stable Rust (no cargo-fuzz): small valid
//! inputs (`fuzz_support/targets.rs`, with two small real files from
//! `../shared/data/crackforest`) are mutated (`fuzz_support/mutate.rs`) —
//! bit flips, byte inserts and deletes, truncation, header lies (PLY counts and formats, PNG and
//! JPEG sizes, COLMAP counts, SPZ headers: an SPZ payload is re-gzipped so they reach the
//! decoder), NaN/Inf and huge numbers, wrong JSON/RON types, repeated lines — and read back
//! through the public API (twin projects: opened and reported,
//! `fuzz_support/project_targets.rs`). Every case must end in `Ok` or a typed error (a
//! `SceneError`; a project's errors as messages) that is one line naming a file of the case,
//! never a panic (caught, with its location) and never more than `CASE_LIMIT`.
//!
//! `cargo test --test fuzz_readers` runs a bounded number of cases (measured in docs/ROBUSTNESS.md).
//! The long run:
//!
//! ```text
//! DAMAGE_TWIN_FUZZ_CASES=200000 cargo test --release --test fuzz_readers -- --nocapture
//! ```
//!
//! Environment: `DAMAGE_TWIN_FUZZ_CASES` (total over all targets), `DAMAGE_TWIN_FUZZ_SEED` (the
//! base seed, default fixed so `cargo test` is deterministic), `DAMAGE_TWIN_FUZZ_ONLY=target:case`
//! (rerun one reported case), `DAMAGE_TWIN_FUZZ_TRACE=1` (print each case before it runs: the
//! last line names the culprit if the process itself dies, e.g. by an allocation abort).

mod fuzz_support;
mod shared_data;

use std::cell::RefCell;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, Once};
use std::time::{Duration, Instant};

use fuzz_support::mutate::{Content, image_size_lie, mutate};
use fuzz_support::project_targets::{project_file_target, survey_files_target};
use fuzz_support::targets::{
    Target, colmap_target, images_target, masks_target, ply_points_target, ply_splats_target,
    project_target, spz_target, transforms_target,
};

/// Total cases of a plain `cargo test`, spread over the 11 targets: 10 000 took 15.7 to 27.4 s
/// in the dev profile on the project's two-core machine shared with other builds
/// (docs/ROBUSTNESS.md), under the 60 s budget.
const DEFAULT_CASES: usize = 10_000;

/// Longest one case may take. Every case here reads files of a few KB (the largest seed is a
/// 28 KB JPEG), which takes milliseconds; seconds mean a reader works on what a lie asked for.
const CASE_LIMIT: Duration = Duration::from_secs(5);

/// A case still running after this is a hang: the watchdog prints it and aborts the process.
const HANG_LIMIT: Duration = Duration::from_secs(60);

fn env_u64(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.trim().parse().ok())
}

/// Cases per target, the base seed and an optional single case to rerun.
struct Config {
    cases: usize,
    seed: u64,
    only: Option<(String, usize)>,
    trace: bool,
}

fn config() -> Config {
    let total = env_u64("DAMAGE_TWIN_FUZZ_CASES").map_or(DEFAULT_CASES, |v| v as usize);
    let only = std::env::var("DAMAGE_TWIN_FUZZ_ONLY").ok().and_then(|v| {
        let (target, case) = v.split_once(':')?;
        Some((target.to_owned(), case.parse().ok()?))
    });
    Config {
        cases: total.div_ceil(TARGETS),
        seed: env_u64("DAMAGE_TWIN_FUZZ_SEED").unwrap_or(0x5eed_2026),
        only,
        trace: std::env::var_os("DAMAGE_TWIN_FUZZ_TRACE").is_some(),
    }
}

/// The number of `fuzz_target!` tests below (the total case count is split over them).
const TARGETS: usize = 11;

// ---------------------------------------------------------------------------------------------
// The runner

thread_local! {
    /// Whether this thread is inside a case (its panics are findings, recorded quietly).
    static IN_CASE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    /// Message and location of the last panic inside a case on this thread.
    static LAST_PANIC: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// A panic hook that records a case's panic instead of printing it, so thousands of cases stay
/// readable (the findings list reports each with its location); any other panic, such as a
/// test's final assertion, goes to the default hook.
fn install_quiet_hook() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !IN_CASE.with(|c| c.get()) {
                return default(info);
            }
            let message = info
                .payload()
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| info.payload().downcast_ref::<String>().cloned())
                .unwrap_or_default();
            let location = info
                .location()
                .map(|l| format!("{}:{}", l.file(), l.line()))
                .unwrap_or_default();
            LAST_PANIC.with(|p| *p.borrow_mut() = Some(format!("{message} at {location}")));
        }));
    });
}

/// Starts a thread that aborts the process, naming the case, when one runs past `HANG_LIMIT`.
/// `started` holds the running case's start in ms since the returned epoch (0: none running,
/// `u64::MAX`: the target is done).
fn watchdog(
    name: &'static str,
    started: &'static AtomicU64,
    current: &'static Mutex<String>,
) -> Instant {
    let epoch = Instant::now();
    std::thread::spawn(move || {
        loop {
            std::thread::sleep(Duration::from_millis(500));
            let at = started.load(Ordering::Relaxed);
            if at == u64::MAX {
                return;
            }
            let now = epoch.elapsed().as_millis() as u64;
            if at != 0 && now.saturating_sub(at) > HANG_LIMIT.as_millis() as u64 {
                let case = current.lock().map(|c| c.clone()).unwrap_or_default();
                eprintln!("fuzz {name}: case hung for over {HANG_LIMIT:?}: {case}");
                std::process::abort();
            }
        }
    });
    epoch
}

/// Runs the target's cases; `None` is a target whose seeds need missing shared data (skipped).
fn run<E: std::fmt::Display>(
    target: impl Into<Option<Target<E>>>,
    started: &'static AtomicU64,
    current: &'static Mutex<String>,
) {
    let Some(target) = target.into() else {
        return;
    };
    install_quiet_hook();
    let cfg = config();
    let epoch = watchdog(target.name, started, current);
    let root = target.dir.path().to_path_buf();
    let root_text = root.display().to_string();
    let base = cfg.seed ^ fxhash(target.name);
    let mut findings = Vec::new();
    let (mut oks, mut errs) = (0usize, 0usize);
    let mut slowest = (Duration::ZERO, String::new());
    let cases: Vec<usize> = match &cfg.only {
        Some((name, case)) if name == target.name => vec![*case],
        Some(_) => Vec::new(),
        None => (0..cfg.cases).collect(),
    };
    let start_all = Instant::now();
    for case in cases {
        let mut rng = fastrand::Rng::with_seed(base.wrapping_add(case as u64));
        let (rel, valid, content) = &target.seeds[rng.usize(..target.seeds.len())];
        let path = root.join(rel);
        let mut bytes = valid.clone();
        let mut log = Vec::new();
        mutate(&mut bytes, *content, &mut rng, &mut log);
        std::fs::write(&path, &bytes).unwrap();
        let description = format!(
            "{}:{case} (DAMAGE_TWIN_FUZZ_SEED={} DAMAGE_TWIN_FUZZ_ONLY={}:{case}) {}: {}",
            target.name,
            cfg.seed,
            target.name,
            rel.display(),
            log.join("; ")
        );
        if cfg.trace {
            eprintln!("fuzz {description}");
        }
        if let Ok(mut c) = current.lock() {
            c.clone_from(&description);
        }
        started.store(epoch.elapsed().as_millis().max(1) as u64, Ordering::Relaxed);
        let t0 = Instant::now();
        IN_CASE.with(|c| c.set(true));
        let outcome = catch_unwind(AssertUnwindSafe(|| (target.read)(&root, &path)));
        IN_CASE.with(|c| c.set(false));
        let elapsed = t0.elapsed();
        started.store(0, Ordering::Relaxed);
        if elapsed > slowest.0 {
            slowest = (elapsed, description.clone());
        }
        match outcome {
            Err(_) => {
                let panic = LAST_PANIC
                    .with(|p| p.borrow_mut().take())
                    .unwrap_or_default();
                findings.push(format!("PANIC {panic}\n    case {description}"));
            }
            Ok(Ok(())) => oks += 1,
            Ok(Err(e)) => {
                errs += 1;
                let message = e.to_string();
                if message.contains('\n') || !message.contains(&root_text) {
                    findings.push(format!(
                        "ERROR NOT ONE LINE NAMING A FILE OF THE CASE: {message:?}\n    case {description}"
                    ));
                }
            }
        }
        if elapsed > CASE_LIMIT {
            findings.push(format!("SLOW {elapsed:?}\n    case {description}"));
        }
        std::fs::write(&path, valid).unwrap();
    }
    started.store(u64::MAX, Ordering::Relaxed);
    eprintln!(
        "fuzz {}: {} cases ({oks} ok, {errs} typed errors) in {:.1} s, slowest {:?} ({}), {} findings",
        target.name,
        oks + errs + findings.len(),
        start_all.elapsed().as_secs_f64(),
        slowest.0,
        slowest.1,
        findings.len()
    );
    if let Some(mb) = damage_twin::metrics::peak_rss_mb() {
        // Lying counts and sizes must be refused, not reserved: the process stays small.
        assert!(mb < 2048.0, "peak RSS {mb} MB");
    }
    assert!(
        findings.is_empty(),
        "{} findings in {}:\n{}",
        findings.len(),
        target.name,
        findings
            .iter()
            .take(20)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
}

/// A stable hash of a target name (FNV-1a), so each target has its own case sequence.
fn fxhash(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
    })
}

macro_rules! fuzz_target {
    ($test:ident, $make:expr) => {
        #[test]
        fn $test() {
            static STARTED: AtomicU64 = AtomicU64::new(0);
            static CURRENT: Mutex<String> = Mutex::new(String::new());
            run($make, &STARTED, &CURRENT);
        }
    };
}

fuzz_target!(
    colmap_binary_never_panics,
    colmap_target("colmap_bin", false)
);
fuzz_target!(colmap_text_never_panics, colmap_target("colmap_txt", true));
fuzz_target!(images_never_panic, images_target());
fuzz_target!(masks_never_panic, masks_target());
fuzz_target!(transforms_json_never_panics, transforms_target());
fuzz_target!(ply_splats_never_panic, ply_splats_target());
fuzz_target!(ply_point_clouds_never_panic, ply_points_target());
fuzz_target!(spz_never_panics, spz_target());
fuzz_target!(twin_ron_never_panics, project_target());
fuzz_target!(projects_never_panic_or_hang, project_file_target());
fuzz_target!(survey_files_never_panic_or_hang, survey_files_target());

/// The mutations themselves: each kind changes its input, and a case is reproducible from its
/// seed (what `DAMAGE_TWIN_FUZZ_ONLY` relies on).
#[test]
fn mutations_are_deterministic_and_change_the_input() {
    let png = {
        let mut bytes = std::io::Cursor::new(Vec::new());
        image::RgbImage::new(4, 4)
            .write_to(&mut bytes, image::ImageFormat::Png)
            .unwrap();
        bytes.into_inner()
    };
    let mut lied = png.clone();
    let what = image_size_lie(&mut lied, &mut fastrand::Rng::with_seed(1)).unwrap();
    assert_ne!(lied, png, "{what}");
    // The lie reaches the decoder: the checksum was fixed, so only the size is wrong.
    let claimed = image::ImageReader::new(std::io::Cursor::new(&lied))
        .with_guessed_format()
        .unwrap()
        .into_dimensions();
    assert!(
        claimed.is_ok_and(|d| d != (4, 4)) || what.contains("4x4"),
        "{what}"
    );
    for content in [Content::Binary, Content::Text] {
        let mut changed = 0;
        for case in 0..200u64 {
            let text =
                b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n2\n";
            let (mut a, mut b) = (text.to_vec(), text.to_vec());
            let (mut la, mut lb) = (Vec::new(), Vec::new());
            mutate(
                &mut a,
                content,
                &mut fastrand::Rng::with_seed(case),
                &mut la,
            );
            mutate(
                &mut b,
                content,
                &mut fastrand::Rng::with_seed(case),
                &mut lb,
            );
            assert_eq!((&a, &la), (&b, &lb));
            changed += usize::from(a != text);
        }
        // A few ops can be no-ops (a token replaced by itself, a lie equal to the old value).
        assert!(changed > 180, "{changed} of 200 cases changed the input");
    }
}
