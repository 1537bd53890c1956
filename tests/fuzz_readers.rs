//! A seeded fuzz harness for every scene reader, on stable Rust (no cargo-fuzz): small valid
//! inputs built here (and two small real files from `../shared/data/crackforest`) are mutated —
//! bit flips, byte inserts and deletes, truncation, header lies (PLY counts and formats, PNG and
//! JPEG sizes, COLMAP counts), NaN/Inf and huge numbers, wrong JSON/RON types, repeated lines —
//! and read back through the public API. Every case must end in `Ok` or a typed `SceneError`
//! whose message is one line naming a file of the case, never a panic (caught, with its
//! location) and never more than `CASE_LIMIT`.
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

use std::cell::RefCell;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, Once};
use std::time::{Duration, Instant};

use damage_twin::scene::colmap::{
    self, CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint,
};
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::ply::{
    read_point_cloud, read_point_cloud_skipping, read_splats, write_point_cloud, write_splats,
};
use damage_twin::scene::project::{PROJECT_FILE, Project, Survey};
use damage_twin::scene::{Dataset, ImageScale, PointCloud, SceneError};
use damage_twin::splats::Splats;
use glam::{Quat, Vec3};

/// Total cases of a plain `cargo test`, spread over the 8 targets: 12 000 took 25 s in the dev
/// profile on the project's two-core machine (docs/ROBUSTNESS.md); 10 000 keeps a plain run
/// near 20 s, well under the 60 s budget when the machine is shared.
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
const TARGETS: usize = 8;

// ---------------------------------------------------------------------------------------------
// Mutations

/// Whether a file is mutated as bytes only or also as text (tokens and lines).
#[derive(Clone, Copy, PartialEq)]
enum Content {
    Binary,
    Text,
}

/// Replacements for a text token: huge, non-finite, negative, empty and wrong-typed values.
const TOKENS: &[&str] = &[
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e20",
    "1e-320",
    "0",
    "-1",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "99999999999999999999999",
    "999999",
    "\"text\"",
    "[]",
    "{}",
    "null",
    "true",
    "abc",
    "",
    "0x10",
    "1.5",
];

/// Little-endian values written over 4 or 8 bytes: counts and ids that lie, and non-finite floats.
fn lie_bytes(rng: &mut fastrand::Rng) -> (Vec<u8>, String) {
    match rng.usize(..10) {
        0 => (u64::MAX.to_le_bytes().to_vec(), "u64::MAX".into()),
        1 => ((1u64 << 40).to_le_bytes().to_vec(), "2^40".into()),
        2 => (u32::MAX.to_le_bytes().to_vec(), "u32::MAX".into()),
        3 => (i32::MIN.to_le_bytes().to_vec(), "i32::MIN".into()),
        4 => (f64::NAN.to_le_bytes().to_vec(), "f64 NaN".into()),
        5 => (f64::INFINITY.to_le_bytes().to_vec(), "f64 Inf".into()),
        6 => (1e300f64.to_le_bytes().to_vec(), "f64 1e300".into()),
        7 => (f32::NAN.to_le_bytes().to_vec(), "f32 NaN".into()),
        8 => (f32::NEG_INFINITY.to_le_bytes().to_vec(), "f32 -Inf".into()),
        _ => (0u64.to_le_bytes().to_vec(), "zero".into()),
    }
}

/// CRC-32 (PNG's, polynomial 0xEDB88320), so a size lie in IHDR is read rather than rejected by
/// the checksum.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// Sizes an image header may claim.
const SIZE_LIES: &[u32] = &[0, 1, 7, 65_535, 100_000, 1 << 20, 0x7fff_ffff, u32::MAX];

/// A header lie about the image size: PNG IHDR (checksum fixed) or JPEG SOF; None when the bytes
/// are neither.
fn image_size_lie(bytes: &mut [u8], rng: &mut fastrand::Rng) -> Option<String> {
    let (w, h) = (
        SIZE_LIES[rng.usize(..SIZE_LIES.len())],
        SIZE_LIES[rng.usize(..SIZE_LIES.len())],
    );
    if bytes.len() >= 33 && bytes.starts_with(b"\x89PNG\r\n\x1a\n") && &bytes[12..16] == b"IHDR" {
        bytes[16..20].copy_from_slice(&w.to_be_bytes());
        bytes[20..24].copy_from_slice(&h.to_be_bytes());
        let crc = crc32(&bytes[12..29]);
        bytes[29..33].copy_from_slice(&crc.to_be_bytes());
        return Some(format!("PNG IHDR claims {w}x{h}"));
    }
    // JPEG: the first SOF0/SOF2 segment holds height then width as u16 after the precision byte.
    let sof = bytes
        .windows(2)
        .position(|m| m[0] == 0xFF && (m[1] == 0xC0 || m[1] == 0xC2))?;
    if sof + 9 > bytes.len() {
        return None;
    }
    let (w, h) = (w.min(65_535) as u16, h.min(65_535) as u16);
    bytes[sof + 5..sof + 7].copy_from_slice(&h.to_be_bytes());
    bytes[sof + 7..sof + 9].copy_from_slice(&w.to_be_bytes());
    Some(format!("JPEG SOF claims {w}x{h}"))
}

/// Byte ranges of the tokens of a text (runs of characters numbers and names are made of).
fn tokens(bytes: &[u8]) -> Vec<(usize, usize)> {
    let is_token = |b: u8| b.is_ascii_alphanumeric() || b"._+-".contains(&b);
    let mut out = Vec::new();
    let mut start = None;
    for (i, &b) in bytes.iter().enumerate() {
        match (is_token(b), start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                out.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s, bytes.len()));
    }
    out
}

/// Byte ranges of the lines (newline included).
fn lines(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, &b) in bytes.iter().enumerate() {
        if b == b'\n' {
            out.push((start, i + 1));
            start = i + 1;
        }
    }
    if start < bytes.len() {
        out.push((start, bytes.len()));
    }
    out
}

/// PLY header lies: the vertex count, the format, a property's type.
fn ply_header_lie(bytes: &mut Vec<u8>, rng: &mut fastrand::Rng) -> Option<String> {
    let end = bytes.windows(10).position(|w| w == b"end_header")?;
    let header = String::from_utf8(bytes[..end].to_vec()).ok()?;
    let new_header = match rng.usize(..3) {
        0 => {
            let counts = [
                "0",
                "1",
                "4",
                "6",
                "1000",
                "4294967296",
                "18446744073709551615",
                "-3",
            ];
            let count = counts[rng.usize(..counts.len())];
            let line = header.lines().find(|l| l.starts_with("element vertex"))?;
            header.replacen(line, &format!("element vertex {count}"), 1)
        }
        1 => {
            let formats = ["ascii", "binary_little_endian", "binary_big_endian"];
            let line = header.lines().find(|l| l.starts_with("format"))?;
            let format = formats[rng.usize(..formats.len())];
            header.replacen(line, &format!("format {format} 1.0"), 1)
        }
        _ => {
            let props: Vec<&str> = header
                .lines()
                .filter(|l| l.starts_with("property"))
                .collect();
            let line = *props.get(rng.usize(..props.len().max(1)))?;
            let name = line.split_whitespace().last()?;
            let types = [
                "uchar",
                "short",
                "int",
                "double",
                "list uchar float",
                "float128",
            ];
            let ty = types[rng.usize(..types.len())];
            header.replacen(line, &format!("property {ty} {name}"), 1)
        }
    };
    bytes.splice(..end, new_header.into_bytes());
    Some("PLY header lie".into())
}

/// Applies one to three random mutations to `bytes`, describing each in `log`.
fn mutate(bytes: &mut Vec<u8>, content: Content, rng: &mut fastrand::Rng, log: &mut Vec<String>) {
    for _ in 0..rng.usize(1..=3) {
        let n = bytes.len();
        // Header lies only where there is such a header (the others would change nothing).
        let is_image = bytes.starts_with(b"\x89PNG") || bytes.starts_with(&[0xFF, 0xD8]);
        let is_ply = bytes.starts_with(b"ply");
        let op = loop {
            let op = rng.usize(..if content == Content::Text { 14 } else { 9 });
            if !(op == 6 && !is_image || op == 7 && !is_ply) {
                break op;
            }
        };
        let what = match op {
            0 => {
                let bits = rng.usize(1..=8);
                for _ in 0..bits {
                    if !bytes.is_empty() {
                        let i = rng.usize(..bytes.len());
                        bytes[i] ^= 1 << rng.u8(..8);
                    }
                }
                format!("{bits} bit flips")
            }
            1 => {
                let at = rng.usize(..=n);
                let len = rng.usize(1..=16);
                let junk: Vec<u8> = (0..len).map(|_| rng.u8(..)).collect();
                bytes.splice(at..at, junk);
                format!("{len} bytes inserted at {at}")
            }
            2 if n > 0 => {
                let at = rng.usize(..n);
                let len = rng.usize(1..=16).min(n - at);
                bytes.drain(at..at + len);
                format!("{len} bytes deleted at {at}")
            }
            3 => {
                let len = rng.usize(..=n);
                bytes.truncate(len);
                format!("truncated to {len} of {n} bytes")
            }
            4 if n >= 8 => {
                // Aligned to 4 most of the time: where counts and floats of binary formats sit.
                let at = rng.usize(..=n - 8) & if rng.bool() { !3 } else { !0 };
                let (value, name) = lie_bytes(rng);
                let len = value.len().min(n - at);
                bytes[at..at + len].copy_from_slice(&value[..len]);
                format!("{name} written at {at}")
            }
            5 if n >= 16 => {
                let from = rng.usize(..n - 8);
                let len = rng.usize(1..=(n - from).min(64));
                let chunk = bytes[from..from + len].to_vec();
                let at = rng.usize(..=n);
                let copies = rng.usize(1..=8);
                for _ in 0..copies {
                    bytes.splice(at..at, chunk.iter().copied());
                }
                format!("{copies} copies of {len} bytes from {from} at {at}")
            }
            6 => image_size_lie(bytes, rng).unwrap_or_else(|| "no image header".into()),
            7 => ply_header_lie(bytes, rng).unwrap_or_else(|| "no PLY header".into()),
            8 if n > 0 => {
                let at = rng.usize(..n);
                let value = [0x00, 0xFF, 0x7F, 0x80, b'\n', b'-'][rng.usize(..6)];
                bytes[at] = value;
                format!("byte {at} set to {value:#x}")
            }
            9..=11 => {
                let spans = tokens(bytes);
                if spans.is_empty() {
                    "no token".into()
                } else {
                    let (s, e) = spans[rng.usize(..spans.len())];
                    let token = TOKENS[rng.usize(..TOKENS.len())];
                    let old = String::from_utf8_lossy(&bytes[s..e]).into_owned();
                    bytes.splice(s..e, token.bytes());
                    format!("token {old:?} at {s} -> {token:?}")
                }
            }
            12 => {
                let spans = lines(bytes);
                if spans.is_empty() {
                    "no line".into()
                } else {
                    let (s, e) = spans[rng.usize(..spans.len())];
                    let line = bytes[s..e].to_vec();
                    // Up to 2000 copies: a repeated record or frame, bounded so a case stays small.
                    let copies = [1, 2, 10, 2000][rng.usize(..4)];
                    for _ in 0..copies {
                        bytes.splice(e..e, line.iter().copied());
                    }
                    format!("line at {s} repeated {copies} times")
                }
            }
            _ => {
                let spans = lines(bytes);
                if spans.is_empty() {
                    "no line".into()
                } else {
                    let (s, e) = spans[rng.usize(..spans.len())];
                    bytes.drain(s..e);
                    format!("line at {s} deleted")
                }
            }
        };
        log.push(what);
    }
}

// ---------------------------------------------------------------------------------------------
// Targets: a folder of valid files, the ones mutated, and how they are read.

struct Target {
    name: &'static str,
    dir: tempfile::TempDir,
    /// Files (relative to `dir`) a case mutates, one per case, with their valid bytes.
    seeds: Vec<(PathBuf, Vec<u8>, Content)>,
    /// Reads the case: the folder and the mutated file.
    read: fn(&Path, &Path) -> Result<(), SceneError>,
}

fn seed(dir: &Path, rel: &str, content: Content) -> (PathBuf, Vec<u8>, Content) {
    let bytes = std::fs::read(dir.join(rel)).unwrap_or_else(|e| panic!("seed {rel}: {e}"));
    (PathBuf::from(rel), bytes, content)
}

fn shared(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel)
}

/// Opens the dataset and loads its first two views at two scales (pixels, masks, undistortion).
fn open_and_load(root: &Path, _: &Path) -> Result<(), SceneError> {
    let ds = Dataset::open(root, &OpenOptions::default())?;
    for index in 0..ds.views.len().min(2) {
        ds.load_view(index, ImageScale::Factor(1))?;
        ds.load_view(index, ImageScale::Factor(2))?;
    }
    Ok(())
}

/// Two cameras (PINHOLE, SIMPLE_RADIAL) of 8 × 6, three images with keypoints, four points.
fn colmap_model(real_jpeg: Option<(u32, u32)>) -> ColmapModel {
    let mut cameras = vec![
        ColmapCamera {
            id: 1,
            model: CameraModel::Pinhole,
            width: 8,
            height: 6,
            params: vec![7.0, 7.5, 4.0, 3.0],
        },
        ColmapCamera {
            id: 2,
            model: CameraModel::SimpleRadial,
            width: 8,
            height: 6,
            params: vec![7.0, 4.0, 3.0, 0.01],
        },
    ];
    let mut images: Vec<ColmapImage> = (1..=3u32)
        .map(|i| ColmapImage {
            id: i,
            qvec: [0.9, 0.1 * i as f64, -0.2, 0.3],
            tvec: [i as f64, -1.5, 4.25],
            camera_id: 1 + i % 2,
            name: format!("im{i}.png"),
            points2d: (0..i as i64)
                .map(|k| ([k as f64 + 0.5, 2.25], if k == 0 { -1 } else { k }))
                .collect(),
        })
        .collect();
    if let Some((w, h)) = real_jpeg {
        cameras.push(ColmapCamera {
            id: 3,
            model: CameraModel::SimplePinhole,
            width: w.into(),
            height: h.into(),
            params: vec![w as f64, w as f64 / 2.0, h as f64 / 2.0],
        });
        images.push(ColmapImage {
            id: 4,
            qvec: [1.0, 0.0, 0.0, 0.0],
            tvec: [0.0, 0.0, 3.0],
            camera_id: 3,
            name: "real.jpg".into(),
            points2d: Vec::new(),
        });
    }
    let points = (1..=4u64)
        .map(|i| ColmapPoint {
            id: i,
            xyz: [i as f64, 0.5, -2.0],
            rgb: [10 * i as u8, 20, 30],
            error: 0.25,
            track: vec![(1, 0), (2, i as u32 % 2)],
        })
        .collect();
    ColmapModel {
        cameras,
        images,
        points,
    }
}

/// `images/im1..3.png`: RGB, RGBA and 16-bit grey, 8 × 6.
fn write_images(root: &Path) {
    std::fs::create_dir_all(root.join("images")).unwrap();
    image::RgbImage::from_fn(8, 6, |x, y| image::Rgb([x as u8 * 30, y as u8 * 40, 90]))
        .save(root.join("images/im1.png"))
        .unwrap();
    image::RgbaImage::from_fn(8, 6, |x, y| {
        image::Rgba([200, x as u8 * 20, 10, y as u8 * 50])
    })
    .save(root.join("images/im2.png"))
    .unwrap();
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(8, 6, |x, y| {
        image::Luma([(x * 8000 + y * 300) as u16])
    })
    .save(root.join("images/im3.png"))
    .unwrap();
}

fn colmap_target(name: &'static str, text: bool) -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let sparse = root.join("sparse/0");
    if text {
        colmap::write_text(&sparse, &colmap_model(None)).unwrap();
    } else {
        colmap::write_binary(&sparse, &colmap_model(None)).unwrap();
    }
    write_images(root);
    let (ext, content) = if text {
        ("txt", Content::Text)
    } else {
        ("bin", Content::Binary)
    };
    let seeds = ["cameras", "images", "points3D"]
        .map(|f| seed(root, &format!("sparse/0/{f}.{ext}"), content))
        .into();
    Target {
        name,
        dir,
        seeds,
        read: open_and_load,
    }
}

/// A COLMAP dataset whose image files are mutated: the three PNGs and a real 28 KB JPEG.
fn images_target() -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    write_images(root);
    let jpeg = shared("crackforest/image/060.jpg");
    std::fs::copy(&jpeg, root.join("images/real.jpg")).unwrap();
    let size = image::image_dimensions(&jpeg).unwrap();
    colmap::write_text(&root.join("sparse/0"), &colmap_model(Some(size))).unwrap();
    let seeds = ["im1.png", "im2.png", "im3.png", "real.jpg"]
        .map(|f| seed(root, &format!("images/{f}"), Content::Binary))
        .into();
    Target {
        name: "images",
        dir,
        seeds,
        read: |root, mutated| {
            let open_and_load_all = || {
                let ds = Dataset::open(root, &OpenOptions::default())?;
                for index in 0..ds.views.len() {
                    ds.load_view(index, ImageScale::Factor(1))?;
                    ds.load_view(index, ImageScale::Width(3))?;
                }
                Ok(())
            };
            first_error([
                damage_twin::scene::load::load_image(mutated).map(drop),
                open_and_load_all(),
            ])
        },
    }
}

/// A dataset with per-class and colour-coded masks, and a real crackforest mask read on its own
/// (its 480 × 320 fits no view here).
fn masks_target() -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    write_images(root);
    colmap::write_binary(&root.join("sparse/0"), &colmap_model(None)).unwrap();
    let masks = root.join("masks");
    std::fs::create_dir_all(masks.join("crack")).unwrap();
    std::fs::create_dir_all(masks.join("spalling")).unwrap();
    image::GrayImage::from_fn(8, 6, |x, y| image::Luma([if x == y { 255 } else { 0 }]))
        .save(masks.join("crack/im1.png"))
        .unwrap();
    // 0/1-valued, as numpy writes masks without scaling.
    image::GrayImage::from_fn(8, 6, |x, _| image::Luma([u8::from(x > 4)]))
        .save(masks.join("spalling/im2.png"))
        .unwrap();
    image::RgbImage::from_fn(8, 6, |x, _| match x {
        0 => image::Rgb([255, 0, 0]),
        1 => image::Rgb([255, 192, 203]),
        2 => image::Rgb([255, 255, 50]),
        _ => image::Rgb([0, 0, 0]),
    })
    .save(masks.join("im1.png"))
    .unwrap();
    std::fs::copy(
        shared("crackforest/masks/060.png"),
        root.join("real_mask.png"),
    )
    .unwrap();
    let seeds = [
        "masks/crack/im1.png",
        "masks/spalling/im2.png",
        "masks/im1.png",
        "real_mask.png",
    ]
    .map(|f| seed(root, f, Content::Binary))
    .into();
    Target {
        name: "masks",
        dir,
        seeds,
        read: |root, mutated| {
            use damage_twin::scene::masks::{default_palette, read_binary_mask, read_colour_mask};
            let views = || {
                let ds = Dataset::open(root, &OpenOptions::default())?;
                for index in 0..ds.views.len().min(2) {
                    ds.load_view(index, ImageScale::Factor(1))?;
                    ds.load_view(index, ImageScale::Factor(4))?;
                }
                Ok(())
            };
            // Root-level masks are colour-coded; the others are per-class binary masks.
            let colour_coded = mutated.parent() == Some(root.join("masks").as_path());
            let direct = if colour_coded {
                read_colour_mask(mutated, &default_palette()).map(drop)
            } else {
                read_binary_mask(mutated).map(drop)
            };
            first_error([direct, views()])
        },
    }
}

fn transforms_target() -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    write_images(root);
    let cloud = PointCloud {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(0.5, 0.5, 0.5)],
        colours: vec![[255, 0, 0], [0, 255, 0], [0, 0, 255]],
    };
    write_point_cloud(&root.join("points.ply"), &cloud).unwrap();
    let json = r#"{
  "camera_angle_x": 0.69,
  "w": 8,
  "h": 6,
  "k1": 0.01,
  "ply_file_path": "points.ply",
  "frames": [
    {"file_path": "images/im1.png", "transform_matrix": [[1, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]},
    {"file_path": "images/im2", "fl_x": 7.5, "transform_matrix": [[0, 0, 1, 4], [0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1]]},
    {"file_path": "./images/im3.png", "w": 8, "h": 6, "cx": 4.2, "transform_matrix": [[1, 0, 0, 0], [0, 0, -1, -4], [0, 1, 0, 0]]}
  ]
}
"#;
    std::fs::write(root.join("transforms.json"), json).unwrap();
    let seeds = vec![
        seed(root, "transforms.json", Content::Text),
        seed(root, "points.ply", Content::Binary),
    ];
    Target {
        name: "transforms",
        dir,
        seeds,
        read: open_and_load,
    }
}

/// A model with SH degree 1 and three label channels, as written (binary little-endian), and
/// the same values as ASCII and big-endian PLY.
fn ply_splats_target() -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let mut splats = Splats::empty(1, 3);
    for g in 0..4 {
        let sh: Vec<f32> = (0..12).map(|i| (g * 12 + i) as f32 * 0.01 - 0.2).collect();
        splats.push(
            Vec3::new(g as f32, -0.5 * g as f32, 1.0),
            Vec3::splat(-2.0 + 0.1 * g as f32),
            Quat::from_xyzw(0.1, 0.2, 0.3, 0.9),
            0.5,
            &sh,
            &[0.1, -0.2, 0.3],
            10 + g as u64,
            g as u16 % 2,
        );
    }
    write_splats(&root.join("model.ply"), &splats).unwrap();
    let binary = std::fs::read(root.join("model.ply")).unwrap();
    let end = binary
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = String::from_utf8(binary[..end].to_vec()).unwrap();
    // Rows of 4-byte floats and a trailing 8-byte double id.
    let row = (end..binary.len()).len() / splats.len();
    let mut ascii = header.replace("binary_little_endian", "ascii");
    let mut big = header
        .replace("binary_little_endian", "binary_big_endian")
        .into_bytes();
    for r in binary[end..].chunks_exact(row) {
        let (floats, id) = r.split_at(row - 8);
        let values: Vec<String> = floats
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()).to_string())
            .chain([f64::from_le_bytes(id.try_into().unwrap()).to_string()])
            .collect();
        ascii.push_str(&values.join(" "));
        ascii.push('\n');
        for b in floats.chunks_exact(4) {
            big.extend(b.iter().rev());
        }
        big.extend(id.iter().rev());
    }
    std::fs::write(root.join("ascii.ply"), ascii).unwrap();
    std::fs::write(root.join("big.ply"), big).unwrap();
    for name in ["ascii.ply", "big.ply"] {
        assert_eq!(read_splats(&root.join(name)).unwrap(), splats, "{name}");
    }
    let seeds = vec![
        seed(root, "model.ply", Content::Binary),
        seed(root, "ascii.ply", Content::Text),
        seed(root, "big.ply", Content::Binary),
    ];
    Target {
        name: "ply_splats",
        dir,
        seeds,
        read: |_, mutated| read_splats(mutated).map(drop),
    }
}

fn ply_points_target() -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let cloud = PointCloud {
        positions: (0..6)
            .map(|i| Vec3::new(i as f32, 0.5, -0.25 * i as f32))
            .collect(),
        colours: (0..6).map(|i| [i as u8 * 40, 100, 200]).collect(),
    };
    write_point_cloud(&root.join("binary.ply"), &cloud).unwrap();
    std::fs::write(
        root.join("ascii.ply"),
        "ply\nformat ascii 1.0\ncomment Open3D float colours\nelement vertex 3\n\
         property double x\nproperty double y\nproperty double z\nproperty float red\n\
         property float green\nproperty float blue\nelement face 0\n\
         property list uchar int vertex_indices\nend_header\n\
         0 0 0 1 0 0\n1.5 -2 3 0 1 0\n0.25 0.5 0.75 0 0 1\n",
    )
    .unwrap();
    let seeds = vec![
        seed(root, "binary.ply", Content::Binary),
        seed(root, "ascii.ply", Content::Text),
    ];
    Target {
        name: "ply_points",
        dir,
        seeds,
        read: |_, mutated| {
            let strict = read_point_cloud(mutated);
            let lenient = read_point_cloud_skipping(mutated);
            // The two differ only in skipping: what the strict reader accepts, the lenient one
            // reads identically without skipping anything.
            if let Ok(cloud) = &strict {
                let (same, skipped) = lenient.as_ref().expect("lenient fails where strict reads");
                assert!(skipped.is_empty() && same == cloud);
            }
            first_error([lenient.map(drop), strict.map(drop)])
        },
    }
}

fn project_target() -> Target {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let mut project = Project::new();
    for (name, date) in [("before", "2024-03-01"), ("after", "2024-09-15")] {
        project
            .add_survey(Survey {
                name: name.into(),
                date: date.into(),
                dataset: format!("surveys/{name}").into(),
                model: Some(format!("surveys/{name}/model.ply").into()),
                metrics: None,
            })
            .unwrap();
    }
    project.settings.scale = ImageScale::Width(960);
    project.save(&root.join(PROJECT_FILE)).unwrap();
    let seeds = vec![seed(root, PROJECT_FILE, Content::Text)];
    Target {
        name: "twin_ron",
        dir,
        seeds,
        read: |_, mutated| Project::load(mutated).map(drop),
    }
}

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

/// The first error of several reads that all ran.
fn first_error<const N: usize>(results: [Result<(), SceneError>; N]) -> Result<(), SceneError> {
    results.into_iter().collect()
}

fn run(target: Target, started: &'static AtomicU64, current: &'static Mutex<String>) {
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
fuzz_target!(twin_ron_never_panics, project_target());

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
