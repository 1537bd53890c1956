//! How every scene reader touches the file system. Only regular files are opened: a named pipe
//! would block `open` forever, a device would read forever, a folder fails late with a vague
//! message; each is refused at once, naming the file. Folders are listed within an entry budget,
//! and a recursive walk never follows a link back into its own ancestors. Knows no formats.

use std::fs::{File, Metadata};
use std::io::Read;
use std::path::{Path, PathBuf};

use crate::scene::SceneError;

/// What a non-regular file is, for the refusal message.
fn kind_of(meta: &Metadata) -> &'static str {
    let ft = meta.file_type();
    if ft.is_dir() {
        return "a folder";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_fifo() {
            return "a named pipe (FIFO)";
        }
        if ft.is_char_device() || ft.is_block_device() {
            return "a device";
        }
        if ft.is_socket() {
            return "a socket";
        }
    }
    "not a regular file"
}

fn not_regular(path: &Path, meta: &Metadata) -> SceneError {
    SceneError::invalid(
        path,
        format!(
            "is {}, not a regular file: only regular files are read",
            kind_of(meta)
        ),
    )
}

/// Opens for reading without blocking: on Linux with `O_NONBLOCK`, so that a FIFO swapped in
/// after the `stat` cannot hang the `open` (a regular file ignores the flag).
fn open_for_reading(path: &Path) -> std::io::Result<File> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    options.open(path)
}

/// Whether anything is at `path`: a file, a folder, a pipe, or a link (even one to nothing).
/// An optional input that is "there" must then be read with `open_regular`, so that a folder,
/// a FIFO or a dangling link put in its place is refused naming it instead of being taken for
/// absent (which `Path::is_file` would do).
pub fn is_present(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok()
}

/// The error of a `metadata` that failed: a link to nothing says so (the plain "No such file"
/// would contradict the listing that shows the link).
fn unreadable(path: &Path, e: std::io::Error) -> SceneError {
    let dangling = e.kind() == std::io::ErrorKind::NotFound
        && std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
    if dangling {
        return SceneError::invalid(path, "is a symbolic link to a file that does not exist");
    }
    SceneError::io(path, e)
}

/// Opens `path` for reading if it is a regular file (links followed); anything else is refused
/// before `open`, and checked again on the opened handle in case the path changed in between.
pub fn open_regular(path: &Path) -> Result<File, SceneError> {
    let meta = std::fs::metadata(path).map_err(|e| unreadable(path, e))?;
    if !meta.is_file() {
        return Err(not_regular(path, &meta));
    }
    let file = open_for_reading(path).map_err(|e| SceneError::io(path, e))?;
    let meta = file.metadata().map_err(|e| SceneError::io(path, e))?;
    if !meta.is_file() {
        return Err(not_regular(path, &meta));
    }
    Ok(file)
}

/// The whole content of a regular file of at most `max_bytes` (a larger one is refused before
/// it is read, naming the limit).
pub fn read_regular(path: &Path, max_bytes: u64) -> Result<Vec<u8>, SceneError> {
    let file = open_regular(path)?;
    let len = file.metadata().map_err(|e| SceneError::io(path, e))?.len();
    if len > max_bytes {
        return Err(SceneError::invalid(
            path,
            format!("file is {len} bytes, more than the {max_bytes} this reader accepts"),
        ));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    // `take` also bounds a file that grows while it is read.
    file.take(max_bytes)
        .read_to_end(&mut bytes)
        .map_err(|e| SceneError::io(path, e))?;
    Ok(bytes)
}

/// The whole content of a regular UTF-8 text file of at most `max_bytes` (`read_regular`).
pub fn read_text(path: &Path, max_bytes: u64) -> Result<String, SceneError> {
    String::from_utf8(read_regular(path, max_bytes)?).map_err(|e| {
        SceneError::invalid(
            path,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        )
    })
}

/// Image width and height from the file's header (the pixels are not decoded).
pub fn image_size(path: &Path) -> Result<(u32, u32), SceneError> {
    let file = open_regular(path)?;
    image::ImageReader::new(std::io::BufReader::new(file))
        .with_guessed_format()
        .map_err(|e| SceneError::io(path, e))?
        .into_dimensions()
        .map_err(|e| SceneError::invalid(path, format!("cannot read the image size: {e}")))
}

/// How many folder entries the listings of one dataset open may still visit, and the folder in
/// which they ran out.
#[derive(Debug)]
pub struct EntryBudget {
    left: usize,
    exhausted_in: Option<PathBuf>,
}

impl EntryBudget {
    pub fn new(entries: usize) -> EntryBudget {
        EntryBudget {
            left: entries,
            exhausted_in: None,
        }
    }

    /// Takes one entry of `dir`; false (and remembered) once none is left.
    fn take(&mut self, dir: &Path) -> bool {
        if self.left == 0 {
            self.exhausted_in.get_or_insert_with(|| dir.to_path_buf());
            return false;
        }
        self.left -= 1;
        true
    }

    /// The folder in which the budget ran out, if it did.
    pub fn exhausted_in(&self) -> Option<&Path> {
        self.exhausted_in.as_deref()
    }
}

/// Paths of the entries directly in `dir` (unsorted), within the budget; an unreadable or
/// missing folder lists nothing.
pub fn list_dir(dir: &Path, budget: &mut EntryBudget) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for entry in entries {
        if !budget.take(dir) {
            break;
        }
        if let Ok(entry) = entry {
            out.push(entry.path());
        }
    }
    out
}

/// Files under `dir` and its sub-folders for which `wanted` holds, as `/`-separated paths
/// relative to `dir`, sorted. Hidden entries are skipped; links are followed except into a folder
/// the walk is already inside (a link to `.` or `..`), sub-folders only `max_depth` deep, and
/// every entry seen takes one from `budget`.
pub fn walk_files(
    dir: &Path,
    max_depth: usize,
    budget: &mut EntryBudget,
    wanted: impl Fn(&Path) -> bool,
) -> Vec<String> {
    struct Walk<'a, F> {
        budget: &'a mut EntryBudget,
        wanted: F,
        max_depth: usize,
        /// Canonical paths of the folders being walked, outermost first.
        ancestors: Vec<PathBuf>,
        out: Vec<String>,
    }
    impl<F: Fn(&Path) -> bool> Walk<'_, F> {
        fn folder(&mut self, dir: &Path, prefix: &str) {
            let Ok(entries) = std::fs::read_dir(dir) else {
                return;
            };
            for entry in entries {
                if !self.budget.take(dir) {
                    return;
                }
                let Ok(entry) = entry else { continue };
                let path = entry.path();
                let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
                    continue;
                };
                if name.starts_with('.') {
                    continue;
                }
                // `metadata` follows links: a link counts as what it points to.
                let Ok(meta) = std::fs::metadata(&path) else {
                    continue;
                };
                let rel = format!("{prefix}{name}");
                if meta.is_dir() {
                    if self.ancestors.len() > self.max_depth {
                        continue;
                    }
                    let Ok(canonical) = path.canonicalize() else {
                        continue;
                    };
                    if self.ancestors.contains(&canonical) {
                        continue;
                    }
                    self.ancestors.push(canonical);
                    self.folder(&path, &format!("{rel}/"));
                    self.ancestors.pop();
                } else if meta.is_file() && (self.wanted)(&path) {
                    self.out.push(rel);
                }
            }
        }
    }
    let Ok(root) = dir.canonicalize() else {
        return Vec::new();
    };
    let mut walk = Walk {
        budget,
        wanted,
        max_depth,
        ancestors: vec![root],
        out: Vec::new(),
    };
    walk.folder(dir, "");
    let mut out = walk.out;
    out.sort();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(target_os = "linux")]
    #[test]
    fn a_named_pipe_and_a_folder_are_refused_without_blocking() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("model.ply");
        let c_path = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: `c_path` is a valid NUL-terminated path that outlives the call.
        assert_eq!(unsafe { libc::mkfifo(c_path.as_ptr(), 0o600) }, 0);
        let err = open_regular(&fifo).unwrap_err().to_string();
        assert!(
            err.contains("model.ply") && err.contains("named pipe"),
            "{err}"
        );
        let err = read_regular(dir.path(), 1 << 20).unwrap_err().to_string();
        assert!(err.contains("a folder"), "{err}");
        let link = dir.path().join("metrics.json");
        std::os::unix::fs::symlink(dir.path().join("gone.json"), &link).unwrap();
        assert!(is_present(&link) && !link.is_file());
        let err = open_regular(&link).unwrap_err().to_string();
        assert!(
            err.contains("metrics.json") && err.contains("link to a file that does not exist"),
            "{err}"
        );
        assert!(!is_present(&dir.path().join("gone.json")));
    }

    #[test]
    fn a_file_over_the_limit_is_refused_before_reading() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("transforms.json");
        std::fs::write(&path, [b' '; 100]).unwrap();
        assert_eq!(read_regular(&path, 100).unwrap().len(), 100);
        let err = read_regular(&path, 99).unwrap_err().to_string();
        assert!(
            err.contains("100 bytes") && err.contains("transforms.json"),
            "{err}"
        );
    }

    #[cfg(unix)]
    #[test]
    fn links_back_into_the_walk_are_not_followed_and_the_budget_stops_it() {
        let dir = tempfile::tempdir().unwrap();
        let images = dir.path().join("images");
        std::fs::create_dir_all(images.join("sub")).unwrap();
        std::fs::write(images.join("a.png"), b"x").unwrap();
        std::fs::write(images.join("sub/b.png"), b"x").unwrap();
        // Six links to the folder itself and one to its parent: followed, each would multiply
        // the walk by seven per level (7^8 ≈ 5.8 million folders at depth 8).
        for i in 0..6 {
            std::os::unix::fs::symlink(".", images.join(format!("loop{i}"))).unwrap();
        }
        std::os::unix::fs::symlink("..", images.join("sub/up")).unwrap();
        let png = |p: &Path| p.extension().is_some_and(|e| e == "png");
        let mut budget = EntryBudget::new(1000);
        let files = walk_files(&images, 8, &mut budget, png);
        assert_eq!(files, ["a.png", "sub/b.png"]);
        assert!(budget.exhausted_in().is_none());
        // 8 entries in images/ and 2 in sub/: a budget of 5 runs out before the walk ends.
        let mut budget = EntryBudget::new(5);
        let files = walk_files(&images, 8, &mut budget, png);
        assert!(files.len() <= 2);
        assert!(budget.exhausted_in().is_some());
    }
}
