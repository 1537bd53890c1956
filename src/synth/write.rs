//! Writers for synth's outputs: 8-bit RGB and grey PNGs, 16-bit depth PNGs (fast, deterministic
//! zlib settings) and the RON manifest. Only encoding and files; no rendering decisions.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ImageBuffer, Luma, Rgb};
use serde::Serialize;

use super::lighting::Lighting;
use super::params::{SynthError, SynthParams};

pub fn create_dir(path: &Path) -> Result<(), SynthError> {
    std::fs::create_dir_all(path).map_err(|source| SynthError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn encoder(path: &Path) -> Result<PngEncoder<BufWriter<File>>, SynthError> {
    let file = File::create(path).map_err(|source| SynthError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(PngEncoder::new_with_quality(
        BufWriter::new(file),
        CompressionType::Fast,
        FilterType::Adaptive,
    ))
}

fn image_error(path: &Path) -> impl FnOnce(image::ImageError) -> SynthError + '_ {
    move |source| SynthError::Image {
        path: path.to_path_buf(),
        source,
    }
}

pub fn rgb_png(path: &Path, width: u32, height: u32, rgb: Vec<u8>) -> Result<(), SynthError> {
    let img: ImageBuffer<Rgb<u8>, _> = ImageBuffer::from_raw(width, height, rgb)
        .ok_or_else(|| SynthError::InvalidParams(format!("{}: buffer size", path.display())))?;
    img.write_with_encoder(encoder(path)?)
        .map_err(image_error(path))
}

pub fn grey_png(path: &Path, width: u32, height: u32, grey: Vec<u8>) -> Result<(), SynthError> {
    let img: ImageBuffer<Luma<u8>, _> = ImageBuffer::from_raw(width, height, grey)
        .ok_or_else(|| SynthError::InvalidParams(format!("{}: buffer size", path.display())))?;
    img.write_with_encoder(encoder(path)?)
        .map_err(image_error(path))
}

/// A 0/1 mask as a 0/255 PNG.
pub fn mask_png(path: &Path, width: u32, height: u32, mask: &[u8]) -> Result<(), SynthError> {
    grey_png(
        path,
        width,
        height,
        mask.iter().map(|&v| if v != 0 { 255 } else { 0 }).collect(),
    )
}

pub fn depth_png(
    path: &Path,
    width: u32,
    height: u32,
    depth_mm: Vec<u16>,
) -> Result<(), SynthError> {
    let img: ImageBuffer<Luma<u16>, _> = ImageBuffer::from_raw(width, height, depth_mm)
        .ok_or_else(|| SynthError::InvalidParams(format!("{}: buffer size", path.display())))?;
    img.write_with_encoder(encoder(path)?)
        .map_err(image_error(path))
}

/// Camera z in metres to the depth PNG encoding (see `DEPTH_ENCODING`).
pub fn depth_to_mm(z: f32) -> u16 {
    if !(z > 0.0) {
        0
    } else {
        (z * 1000.0).round().clamp(1.0, 65535.0) as u16
    }
}

pub const DEPTH_ENCODING: &str = "truth/depth/<stem>.png: 16-bit grey PNG, camera-space z (along the \
    optical axis, COLMAP convention) in millimetres; 0 = sky (no surface), 65535 = 65.535 m or farther";

pub const JOINT_FRAME: &str = "joint: sparse/0 holds survey 1's images (`old_images`, survey-1 \
    names) and this survey's (`images`, named new-view-NNN.png) in one random similarity frame with \
    pose noise, as a user's COLMAP run over old and new images would; truth/joint_frame.json gives \
    the similarity (twin = survey 1 world frame -> joint frame) and the noise. images/ and \
    masks/<class>/ hold both surveys' files (survey 1's copied byte for byte); truth/ describes \
    the new images only. truth/depth and truth/quantities.json stay in metres of the world frame \
    (multiply depth by the similarity's scale for joint units)";

/// `truth/manifest.ron`: everything needed to regenerate and interpret a survey.
#[derive(Serialize)]
pub struct Manifest {
    pub generator: String,
    pub survey: u32,
    pub params: SynthParams,
    pub lighting: Lighting,
    /// This survey's own images (survey 2's are `new-view-NNN.png` in the joint frame).
    pub images: Vec<String>,
    /// Survey 1's images, also in this survey's model (joint frame only; empty otherwise).
    pub old_images: Vec<String>,
    pub components: Vec<(u8, String)>,
    pub depth: String,
    pub masks: String,
    pub mask_corrupted_images: Vec<String>,
    pub damage: DamageSummary,
    pub world: String,
    /// Which frame sparse/0 is in.
    pub frame: String,
    /// The schema of truth/quantities.json.
    pub quantities: String,
}

#[derive(Serialize)]
pub struct DamageSummary {
    pub cracks: usize,
    pub spalls: usize,
    pub spalls_with_rebar: usize,
}

/// `value` as pretty JSON with a final newline.
pub fn json(path: &Path, value: &impl Serialize) -> Result<(), SynthError> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| SynthError::InvalidParams(format!("{}: {e}", path.display())))?;
    let io = |source: std::io::Error| SynthError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut f = File::create(path).map_err(io)?;
    f.write_all(text.as_bytes()).map_err(io)?;
    f.write_all(b"\n").map_err(io)
}

pub fn manifest(path: &Path, manifest: &Manifest) -> Result<(), SynthError> {
    let text = ron::ser::to_string_pretty(manifest, ron::ser::PrettyConfig::default())
        .map_err(|e| SynthError::InvalidParams(format!("{}: {e}", path.display())))?;
    let io = |source: std::io::Error| SynthError::Io {
        path: PathBuf::from(path),
        source,
    };
    let mut f = File::create(path).map_err(io)?;
    f.write_all(text.as_bytes()).map_err(io)?;
    f.write_all(b"\n").map_err(io)
}
