//! The built-in demo building in a cache folder: generated on first use (atomically: into a
//! temporary folder renamed when complete), opened at once on later runs. The viewer and the
//! headless demo share it; the generation itself is `generate`.

use std::path::{Path, PathBuf};

use crate::synth::{SynthError, SynthParams};

/// Bumped when the demo's generation settings change, so stale caches are regenerated.
const DEMO_VERSION: &str = "demo-v2";
const MARKER: &str = ".damage-twin-demo";

/// The demo the viewer trains live: synth's building at 960×540 (issue 7's stated scale), fewer
/// views than synth's 60 so that the first run generates it in well under a minute on 2 cores.
pub const DEMO_WIDTH: u32 = 960;
pub const DEMO_HEIGHT: u32 = 540;
pub const DEMO_VIEWS: usize = 32;

/// Where the demo is cached: `$DAMAGE_TWIN_DEMO_DIR`, else `$XDG_CACHE_HOME/damage-twin/demo`,
/// else `~/.cache/damage-twin/demo`, else the system temporary folder.
pub fn cache_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("DAMAGE_TWIN_DEMO_DIR") {
        return PathBuf::from(dir);
    }
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir);
    base.join("damage-twin").join("demo")
}

/// True when `dir` holds a complete demo of this version.
pub fn is_complete(dir: &Path) -> bool {
    std::fs::read_to_string(dir.join(MARKER)).is_ok_and(|v| v.trim() == DEMO_VERSION)
}

/// The survey folder (the dataset to open) inside a demo folder.
pub fn dataset_dir(dir: &Path) -> PathBuf {
    dir.join("survey-1")
}

/// Generates the demo (`synth`'s demo building at both survey dates, `survey-1/` and
/// `survey-2/`; `views` 0 keeps synth's count for survey 1) into `dir` unless it is already
/// there, and returns survey 1's dataset folder. `progress(fraction, message)` is called from
/// the generating threads. The folder appears only once complete.
pub fn ensure(
    dir: &Path,
    views: usize,
    width: u32,
    height: u32,
    progress: &(dyn Fn(f32, &str) + Sync),
) -> Result<PathBuf, SynthError> {
    if is_complete(dir) {
        progress(1.0, "cached");
        return Ok(dataset_dir(dir));
    }
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| SynthError::Io { path, source }
    };
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(parent).map_err(io(parent))?;
    let tmp = parent.join(format!(".demo-tmp-{}", std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(io(&tmp))?;
    }
    let mut params = SynthParams::demo(&tmp);
    params.surveys = 2;
    params.width = width;
    params.height = height;
    if views > 0 {
        params.views = views;
    }
    let tick = |done: usize, total: usize| {
        progress(
            done as f32 / total.max(1) as f32,
            &format!("rendering view {done} of {total}"),
        )
    };
    let result = crate::synth::generate(&params, &tick).and_then(|_| {
        let marker = tmp.join(MARKER);
        std::fs::write(&marker, DEMO_VERSION).map_err(io(&marker))?;
        if dir.exists() {
            std::fs::remove_dir_all(dir).map_err(io(dir))?;
        }
        std::fs::rename(&tmp, dir).map_err(io(dir))
    });
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result.map(|()| dataset_dir(dir))
}
