//! Where the tests find the shared test data (`../shared/data` beside the repository, README
//! "Test data"), and the skip when it is not there: a fresh clone has no `../shared`, and its
//! `cargo test` must still pass. Every test that reads the shared data asks for it here, so the
//! skip is the same line everywhere:
//!
//! ```text
//! skipped: ../shared/data/opensfm_lund missing (see README: test data)
//! ```
//!
//! Stable Rust gives a test no way to mark itself ignored once it runs, so a skipped test is
//! counted as passed by the harness; the line goes straight to stderr (the harness captures
//! `eprintln!` of passing tests), and the binary prints how many of its tests skipped when it
//! exits. `DAMAGE_TWIN_REQUIRE_SHARED_DATA=1` turns a skip into a failure, for machines (CI) that
//! must run the full suite.
#![allow(dead_code)]

use std::io::Write;
use std::path::{Component, Path, PathBuf};
use std::sync::Once;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Set to `1` to fail instead of skip when the shared data is missing.
const REQUIRE_ENV: &str = "DAMAGE_TWIN_REQUIRE_SHARED_DATA";

/// Tests of this binary that skipped (or skipped a part) for missing data.
static SKIPPED: AtomicUsize = AtomicUsize::new(0);
static SUMMARY_AT_EXIT: Once = Once::new();

/// `../shared/data/<relative>` (`"opensfm_lund"`, `"crackforest/image/060.jpg"`) when its data
/// set (the first component) is there; otherwise prints the skip line and returns `None`, and the
/// test returns early. Only a missing data set skips: a data set that is there but lacks a file
/// fails the test that reads it, as a broken copy should.
pub fn path(relative: &str) -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    let set = match Path::new(relative).components().next() {
        Some(Component::Normal(set)) => set.to_owned(),
        _ => panic!("shared data is named by its folder first, not {relative:?}"),
    };
    if root.join(&set).is_dir() {
        return Some(root.join(relative));
    }
    let line = format!(
        "../shared/data/{} missing (see README: test data)",
        set.to_string_lossy()
    );
    if std::env::var(REQUIRE_ENV).is_ok_and(|v| v == "1") {
        panic!("{line}, and {REQUIRE_ENV}=1");
    }
    SKIPPED.fetch_add(1, Ordering::Relaxed);
    SUMMARY_AT_EXIT.call_once(|| {
        // SAFETY: `atexit` only records the function pointer; `print_summary` is a plain
        // `extern "C"` function that cannot unwind (it ignores write errors).
        unsafe { atexit(print_summary) };
    });
    // Written to stderr directly, past the harness's capture, so a passing run shows it.
    let _ = writeln!(std::io::stderr(), "skipped: {line}");
    None
}

// The C runtime's exit hooks: run after the harness's own summary, whether the binary passes
// (main returns) or fails (`process::exit`), which no Rust destructor of a static does.
unsafe extern "C" {
    fn atexit(hook: extern "C" fn()) -> std::ffi::c_int;
}

extern "C" fn print_summary() {
    let skipped = SKIPPED.load(Ordering::Relaxed);
    let _ = writeln!(
        std::io::stderr(),
        "shared data: {skipped} test(s) of this binary skipped, their data missing \
         (see README: test data)"
    );
}
