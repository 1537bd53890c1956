//! SPZ, Niantic's compressed splat format (versions 2 and 3), to and from `Splats`: the layout
//! and quantisation of the reference library (nianticlabs/spz `src/cc/load-spz.cc`), which
//! SuperSplat, Babylon and other viewers read. Damage label channels, ids, surveys and state
//! bits have no place in SPZ and are not written; a read model has none.
//!
//! The bytes are one gzip stream holding a 16-byte header (magic `0x5053474e`, version,
//! Gaussian count, SH degree, fractional bits, flags, reserved; little-endian) and then each
//! attribute for all Gaussians in turn:
//!
//! | attribute | bytes | encoding (reference's) | decoding error |
//! | --- | --- | --- | --- |
//! | position | 9 | 24-bit fixed point, `fractional_bits` (12: 1/4096) | ≤ half a step |
//! | alpha | 1 | `sigmoid(raw_opacity) · 255` | opacity ≤ 0.5/255 |
//! | colour | 3 | SH DC `· 0.15 · 255 + 127.5` | DC ≤ 0.5/38.25 (colour ≤ 0.0037) |
//! | scale | 3 | `(log_scale + 10) · 16`, clamped to [−10, 5.94] | log ≤ 1/32 |
//! | rotation | 3 (v2) or 4 (v3) | v2: x, y, z at 8 bits, w ≥ 0 derived; v3: smallest three at 9 bits + sign, index of the largest | v3 0.21°; v2 2.2° (\|w\| ≥ 0.3), 9.9° as w → 0 |
//! | SH rest | 3·((d+1)²−1) | `x · 128 + 128` clamped to [−1, 1), then 5 bits (degree 1) or 4 bits (2, 3): `SpzOptions::sh_bits` | ≤ 4.5/128, ≤ 8.5/128 at 5, 4 bits |
//!
//! Coordinates: SPZ stores right-up-back (RUB, three.js); our frame is COLMAP's (x right, y
//! down, z forward: RDF), the frame of the 3DGS PLY we write and that the reference calls "the
//! PLY coordinate system". So writing turns the model half a turn about x, `(x, y, z) → (x, −y,
//! −z)`: positions and the quaternion's y, z negate, and each SH coefficient takes its basis
//! function's parity (`FLIP_SH`, the reference's `flipSh` for RDF → RUB). Reading undoes it. A
//! file written here therefore unpacks in the reference (`loadSpz` into RDF) to our PLY's values
//! within the bounds above (checked against the reference compiled to wasm, `@spz-loader/core`
//! 0.3.1, on the fox model: docs/ENGINE.md), and viewers that follow the documented RUB show it
//! the way up they show our PLY. Niantic's own `ply_to_spz` converts with no coordinate system and
//! so leaves PLY files unturned (nianticlabs/spz#84 asks why); a reader that assumes that shows our
//! files upside down.
//!
//! Files with extensions (flag `0x2`, e.g. Adobe's SH range) and version 4 (zstd) are refused
//! with a message, not misread. `encode` and `decode` are pure; `read_spz` and `write_spz` add
//! the file, through `scene`'s regular-file read and atomic write (the one place in `splats`
//! that touches a file).

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use flate2::Compression;
use flate2::read::GzDecoder;
use flate2::write::GzEncoder;
use glam::{Quat, Vec3, Vec4};

use crate::scene::SceneError;
use crate::scene::atomic::write_atomic;
use crate::scene::files::read_regular;
use crate::splats::Splats;
use crate::splats::model::{MAX_SH_DEGREE, logit, sh_coeffs_for_degree, sigmoid};

/// `NGSP`, little-endian.
pub const MAGIC: u32 = 0x5053_474e;
/// The reference loader refuses more (`maxPointsToRead`); so does this reader, and this writer
/// refuses to write a file the reference would not load.
pub const MAX_POINTS: usize = 10_000_000;
/// The reference's choice: 12 fractional bits, 1/4096 of a unit, ±2048 units of range. Larger
/// scenes get fewer bits (`fractional_bits_for`); every reader reads the header's.
pub const DEFAULT_FRACTIONAL_BITS: u8 = 12;
/// Largest compressed file read: a 10 M-Gaussian degree-3 file decompresses to 650 MB, and
/// gzip grows incompressible data by a few bytes per 32 KB block.
pub const MAX_FILE_BYTES: u64 = 1 << 30;

const HEADER_BYTES: usize = 16;
/// The reference's `colorScale`: DC is stored at 0.15, not SH_C0 (0.282), so that base colours
/// somewhat outside [0, 1] (brought back by the higher bands) still fit a byte.
const COLOR_SCALE: f32 = 0.15;
const FLAG_ANTIALIASED: u8 = 0x1;
const FLAG_EXTENSIONS: u8 = 0x2;
/// Largest 24-bit signed magnitude.
const FIXED24_MAX: f32 = 8_388_607.0;
/// The reference's bits kept of each SH byte: 5 for degree 1, 4 for degrees 2 and 3.
pub const REFERENCE_SH_BITS: [u8; 2] = [5, 4];

/// RDF → RUB, a half-turn about x: the sign of each position axis.
const FLIP_POSITION: Vec3 = Vec3::new(1.0, -1.0, -1.0);
/// The sign of SH coefficient `k = 1..=15` under `(x, y, z) → (x, −y, −z)`: `Y_k(F d) =
/// FLIP_SH[k − 1] · Y_k(d)` (tested against `sh::sh_basis`).
const FLIP_SH: [f32; 15] = [
    -1.0, -1.0, 1.0, // degree 1: y, z, x
    -1.0, 1.0, 1.0, -1.0, 1.0, // degree 2: xy, yz, 1, xz, 1
    -1.0, 1.0, -1.0, -1.0, 1.0, -1.0, 1.0, // degree 3: y, xyz, y, z, x, z, x
];

/// The rotation encoding: 3 writes smallest-three (the reference's default since 2025); 2 is
/// for readers that know only version 2.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SpzVersion {
    V2,
    #[default]
    V3,
}

impl SpzVersion {
    pub fn number(self) -> u32 {
        match self {
            SpzVersion::V2 => 2,
            SpzVersion::V3 => 3,
        }
    }

    fn rotation_bytes(self) -> usize {
        match self {
            SpzVersion::V2 => 3,
            SpzVersion::V3 => 4,
        }
    }
}

/// How a model is written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpzOptions {
    pub version: SpzVersion,
    /// Bits kept of each SH byte, degree 1 then degrees 2 and 3 (1..=8). Readers need not know
    /// them: a byte decodes to `(q − 128) / 128` whatever was kept; fewer bits give gzip more
    /// repeats and the colour more error.
    pub sh_bits: [u8; 2],
}

impl Default for SpzOptions {
    fn default() -> Self {
        SpzOptions {
            version: SpzVersion::default(),
            sh_bits: REFERENCE_SH_BITS,
        }
    }
}

impl SpzOptions {
    pub fn new(version: SpzVersion) -> SpzOptions {
        SpzOptions {
            version,
            ..SpzOptions::default()
        }
    }
}

/// The header of an SPZ file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpzHeader {
    pub version: SpzVersion,
    pub points: u32,
    pub sh_degree: u8,
    pub fractional_bits: u8,
    pub flags: u8,
}

impl SpzHeader {
    /// Trained with mip-splatting's antialiasing; our renderer does not compensate for it.
    pub fn antialiased(&self) -> bool {
        self.flags & FLAG_ANTIALIASED != 0
    }

    /// One step of the fixed-point positions, in scene units.
    pub fn position_step(&self) -> f32 {
        (-f32::from(self.fractional_bits)).exp2()
    }

    /// Bytes of the attribute data after the header.
    pub fn payload_bytes(&self) -> usize {
        let sh_rest = sh_coeffs_for_degree(u32::from(self.sh_degree)) - 1;
        self.points as usize * (9 + 1 + 3 + 3 + self.version.rotation_bytes() + 3 * sh_rest)
    }

    fn to_bytes(self) -> [u8; HEADER_BYTES] {
        let mut out = [0u8; HEADER_BYTES];
        out[0..4].copy_from_slice(&MAGIC.to_le_bytes());
        out[4..8].copy_from_slice(&self.version.number().to_le_bytes());
        out[8..12].copy_from_slice(&self.points.to_le_bytes());
        out[12] = self.sh_degree;
        out[13] = self.fractional_bits;
        out[14] = self.flags;
        out
    }

    fn parse(bytes: &[u8; HEADER_BYTES]) -> Result<SpzHeader, SpzProblem> {
        let word =
            |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        if word(0) != MAGIC {
            return Err(SpzProblem::BadMagic(word(0)));
        }
        let version = match word(4) {
            2 => SpzVersion::V2,
            3 => SpzVersion::V3,
            other => return Err(SpzProblem::UnsupportedVersion(other)),
        };
        let points = word(8);
        if points as usize > MAX_POINTS {
            return Err(SpzProblem::TooManyPoints(points as usize));
        }
        let (sh_degree, fractional_bits, flags) = (bytes[12], bytes[13], bytes[14]);
        if u32::from(sh_degree) > MAX_SH_DEGREE {
            return Err(SpzProblem::ShDegree(u32::from(sh_degree)));
        }
        // The reference computes `1 << fractionalBits` in an int.
        if fractional_bits > 30 {
            return Err(SpzProblem::FractionalBits(fractional_bits));
        }
        if flags & FLAG_EXTENSIONS != 0 {
            return Err(SpzProblem::Extensions);
        }
        Ok(SpzHeader {
            version,
            points,
            sh_degree,
            fractional_bits,
            flags,
        })
    }
}

/// What is wrong with SPZ bytes, or with a model that cannot be written as SPZ.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SpzProblem {
    #[error("not a readable gzip stream ({0}): SPZ files are gzip-compressed")]
    Gzip(String),
    #[error("{0} bytes after decompression, fewer than the 16-byte SPZ header")]
    ShortHeader(usize),
    #[error("magic {0:#010x} is not SPZ's 0x5053474e")]
    BadMagic(u32),
    #[error("SPZ version {0} is not supported (2 and 3 are; 4 is zstd-compressed)")]
    UnsupportedVersion(u32),
    #[error("{0} Gaussians: SPZ readers refuse more than {MAX_POINTS}")]
    TooManyPoints(usize),
    #[error("SH degree {0} is not supported (0..=3)")]
    ShDegree(u32),
    #[error("{0} fractional bits for positions: at most 30")]
    FractionalBits(u8),
    #[error("the file has SPZ extensions (flag 0x2), which this reader does not decode")]
    Extensions,
    #[error(
        "the header promises {points} Gaussians at SH degree {sh_degree} ({expected} bytes of \
         data) but the stream holds {actual}"
    )]
    LengthMismatch {
        points: u32,
        sh_degree: u8,
        expected: usize,
        /// Capped at `expected + 1`: the stream is not read further.
        actual: usize,
    },
    #[error("SH bits {0:?}: each must be 1..=8")]
    ShBits([u8; 2]),
    #[error("the model is inconsistent: {0}")]
    Inconsistent(String),
    #[error("Gaussian {gaussian}: {what} is NaN or infinite")]
    NonFinite { gaussian: usize, what: &'static str },
    #[error("Gaussian {gaussian}: rotation is all zeros")]
    ZeroRotation { gaussian: usize },
    #[error("coordinate {0} is too far from the origin for SPZ's 24-bit positions (|x| < 8388608)")]
    PositionRange(f32),
}

/// An SPZ read or write that failed, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum SpzError {
    /// Opening, reading or writing the file.
    #[error(transparent)]
    File(#[from] SceneError),
    #[error("{}: {problem}", path.display())]
    Format { path: PathBuf, problem: SpzProblem },
}

/// The SPZ bytes of `splats`, with the header they carry.
pub fn encode(splats: &Splats, options: &SpzOptions) -> Result<(Vec<u8>, SpzHeader), SpzProblem> {
    check_encodable(splats)?;
    if !options.sh_bits.iter().all(|b| (1..=8).contains(b)) {
        return Err(SpzProblem::ShBits(options.sh_bits));
    }
    let version = options.version;
    let buckets = options.sh_bits.map(|b| 1i32 << (8 - b));
    let n = splats.len();
    let max_abs = splats
        .means
        .iter()
        .map(|m| m.abs().max_element())
        .fold(0.0f32, f32::max);
    let header = SpzHeader {
        version,
        points: n as u32,
        sh_degree: splats.sh_degree as u8,
        fractional_bits: fractional_bits_for(max_abs)?,
        flags: 0,
    };
    let k = splats.sh_coeffs();
    let mut data = Vec::with_capacity(HEADER_BYTES + header.payload_bytes());
    data.extend_from_slice(&header.to_bytes());
    let step = (f32::from(header.fractional_bits)).exp2();
    for mean in &splats.means {
        for v in (*mean * FLIP_POSITION).to_array() {
            let fixed = (v * step).round() as i32;
            data.extend_from_slice(&fixed.to_le_bytes()[..3]);
        }
    }
    data.extend(
        splats
            .raw_opacities
            .iter()
            .map(|&a| to_u8(sigmoid(a) * 255.0)),
    );
    for g in 0..n {
        let dc = &splats.sh_of(g)[..3];
        data.extend(dc.iter().map(|&c| to_u8(c * (COLOR_SCALE * 255.0) + 127.5)));
    }
    for s in &splats.log_scales {
        data.extend(s.to_array().map(|v| to_u8((v + 10.0) * 16.0)));
    }
    for q in &splats.rotations {
        let q = flip_quat(unit_quat(*q));
        match version {
            SpzVersion::V2 => data.extend_from_slice(&pack_first_three(q)),
            SpzVersion::V3 => data.extend_from_slice(&pack_smallest_three(q).to_le_bytes()),
        }
    }
    for g in 0..n {
        let sh = splats.sh_of(g);
        for j in 1..k {
            let bucket = if j < 4 { buckets[0] } else { buckets[1] };
            for c in 0..3 {
                data.push(quantize_sh(FLIP_SH[j - 1] * sh[j * 3 + c], bucket));
            }
        }
    }
    debug_assert_eq!(data.len(), HEADER_BYTES + header.payload_bytes());
    let mut gz = GzEncoder::new(Vec::with_capacity(data.len() / 3), Compression::best());
    gz.write_all(&data)
        .map_err(|e| SpzProblem::Gzip(e.to_string()))?;
    let bytes = gz.finish().map_err(|e| SpzProblem::Gzip(e.to_string()))?;
    Ok((bytes, header))
}

/// A model from SPZ bytes: every value finite, rotations unit length, no label channels, ids by
/// index, survey 0, never damage, no state bits (as a PLY without damage-twin's extras).
pub fn decode(compressed: &[u8]) -> Result<(Splats, SpzHeader), SpzProblem> {
    let mut stream = GzDecoder::new(compressed);
    let mut head = Vec::with_capacity(HEADER_BYTES);
    (&mut stream)
        .take(HEADER_BYTES as u64)
        .read_to_end(&mut head)
        .map_err(|e| SpzProblem::Gzip(e.to_string()))?;
    let head: [u8; HEADER_BYTES] = head
        .as_slice()
        .try_into()
        .map_err(|_| SpzProblem::ShortHeader(head.len()))?;
    let header = SpzHeader::parse(&head)?;
    let expected = header.payload_bytes();
    // Grown as data arrives (not sized from the header), so a lying count costs only the bytes
    // really there; one byte past the promise tells "too long" from "exact".
    let mut data = Vec::new();
    stream
        .take(expected as u64 + 1)
        .read_to_end(&mut data)
        .map_err(|e| SpzProblem::Gzip(e.to_string()))?;
    if data.len() != expected {
        return Err(SpzProblem::LengthMismatch {
            points: header.points,
            sh_degree: header.sh_degree,
            expected,
            actual: data.len(),
        });
    }
    Ok((unpack(&data, &header), header))
}

/// Writes `splats` as SPZ to `path` atomically; returns the header written and the file size.
pub fn write_spz(
    path: &Path,
    splats: &Splats,
    options: &SpzOptions,
) -> Result<(SpzHeader, u64), SpzError> {
    let (bytes, header) = encode(splats, options).map_err(|problem| SpzError::Format {
        path: path.to_path_buf(),
        problem,
    })?;
    write_atomic(path, |w| w.write_all(&bytes))?;
    Ok((header, bytes.len() as u64))
}

/// Reads an SPZ file (a regular file of at most `MAX_FILE_BYTES`).
pub fn read_spz(path: &Path) -> Result<(Splats, SpzHeader), SpzError> {
    let bytes = read_regular(path, MAX_FILE_BYTES)?;
    decode(&bytes).map_err(|problem| SpzError::Format {
        path: path.to_path_buf(),
        problem,
    })
}

/// The most fractional bits (up to the reference's 12) at which `max_abs` fits 24 bits.
pub fn fractional_bits_for(max_abs: f32) -> Result<u8, SpzProblem> {
    let mut bits = DEFAULT_FRACTIONAL_BITS;
    while bits > 0 && (max_abs * f32::from(bits).exp2()).round() > FIXED24_MAX {
        bits -= 1;
    }
    if max_abs.round() > FIXED24_MAX {
        return Err(SpzProblem::PositionRange(max_abs));
    }
    Ok(bits)
}

fn check_encodable(splats: &Splats) -> Result<(), SpzProblem> {
    splats.check_lengths().map_err(SpzProblem::Inconsistent)?;
    if splats.sh_degree > MAX_SH_DEGREE {
        return Err(SpzProblem::ShDegree(splats.sh_degree));
    }
    if splats.len() > MAX_POINTS {
        return Err(SpzProblem::TooManyPoints(splats.len()));
    }
    for g in 0..splats.len() {
        let bad = |what| SpzProblem::NonFinite { gaussian: g, what };
        if !splats.means[g].is_finite() {
            return Err(bad("position"));
        }
        if !splats.log_scales[g].is_finite() {
            return Err(bad("log scale"));
        }
        if !splats.rotations[g].is_finite() {
            return Err(bad("rotation"));
        }
        if !splats.raw_opacities[g].is_finite() {
            return Err(bad("opacity"));
        }
        if !splats.sh_of(g).iter().all(|v| v.is_finite()) {
            return Err(bad("SH coefficient"));
        }
        if splats.rotations[g].to_array().iter().all(|&v| v == 0.0) {
            return Err(SpzProblem::ZeroRotation { gaussian: g });
        }
    }
    Ok(())
}

fn unpack(data: &[u8], header: &SpzHeader) -> Splats {
    let n = header.points as usize;
    let k = sh_coeffs_for_degree(u32::from(header.sh_degree));
    let rot_bytes = header.version.rotation_bytes();
    let (positions, rest) = data.split_at(9 * n);
    let (alphas, rest) = rest.split_at(n);
    let (colours, rest) = rest.split_at(3 * n);
    let (scales, rest) = rest.split_at(3 * n);
    let (rotations, sh_rest) = rest.split_at(rot_bytes * n);
    let step = header.position_step();
    let mut splats = Splats::empty(u32::from(header.sh_degree), 0);
    let mut sh = vec![0.0f32; k * 3];
    for g in 0..n {
        let p = &positions[9 * g..9 * g + 9];
        let fixed = |i: usize| {
            // Sign-extend the 24-bit value through the top byte of an i32.
            i32::from_le_bytes([0, p[3 * i], p[3 * i + 1], p[3 * i + 2]]) >> 8
        };
        let mean = Vec3::new(fixed(0) as f32, fixed(1) as f32, fixed(2) as f32) * step;
        let s = &scales[3 * g..3 * g + 3];
        let log_scale = Vec3::new(s[0].into(), s[1].into(), s[2].into()) / 16.0 - 10.0;
        let r = &rotations[rot_bytes * g..rot_bytes * (g + 1)];
        let rotation = match header.version {
            SpzVersion::V2 => unpack_first_three([r[0], r[1], r[2]]),
            SpzVersion::V3 => unpack_smallest_three(u32::from_le_bytes([r[0], r[1], r[2], r[3]])),
        };
        for c in 0..3 {
            sh[c] = (f32::from(colours[3 * g + c]) / 255.0 - 0.5) / COLOR_SCALE;
        }
        let stored = &sh_rest[3 * (k - 1) * g..3 * (k - 1) * (g + 1)];
        for j in 1..k {
            for c in 0..3 {
                let q = f32::from(stored[(j - 1) * 3 + c]);
                sh[j * 3 + c] = FLIP_SH[j - 1] * (q - 128.0) / 128.0;
            }
        }
        // Alpha 0 or 255 is a logit of ∓∞: `logit` clamps to 1e-6 from either end.
        let raw_opacity = logit(f32::from(alphas[g]) / 255.0);
        splats.push(
            mean * FLIP_POSITION,
            log_scale,
            flip_quat(rotation),
            raw_opacity,
            &sh,
            &[],
            g as u64,
            0,
        );
    }
    splats
}

/// `q` at unit length, also where its squared length overflows or underflows f32: scaled by
/// its largest component first. `q` is finite and not all zeros (`check_encodable`).
fn unit_quat(q: Quat) -> Quat {
    let largest = q.to_array().iter().fold(0.0f32, |m, v| m.max(v.abs()));
    Quat::from_vec4(Vec4::from(q) / largest).normalize()
}

/// The quaternion of the half-turned frame: `F R F` keeps x and negates y and z. Its own
/// inverse.
fn flip_quat(q: Quat) -> Quat {
    Quat::from_xyzw(q.x, -q.y, -q.z, q.w)
}

/// `std::round` then clamp to a byte, as the reference's `toUint8`.
fn to_u8(v: f32) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// The reference's v2/v3 SH quantiser (`quantizeSHLegacy`, which its decoder inverts as
/// `(q − 128) / 128`): 8 bits, then rounded to a multiple of `bucket` so gzip finds repeats.
fn quantize_sh(x: f32, bucket: i32) -> u8 {
    let q = (x * 128.0).round() as i32 + 128;
    // Integer division truncates towards zero, as in C++.
    let q = (q + bucket / 2) / bucket * bucket;
    q.clamp(0, 255) as u8
}

/// Version 2: x, y, z of the unit quaternion with w ≥ 0, at 8 bits each.
fn pack_first_three(q: Quat) -> [u8; 3] {
    let q = if q.w < 0.0 { -q } else { q };
    [q.x, q.y, q.z].map(|v| to_u8(v * 127.5 + 127.5))
}

fn unpack_first_three(r: [u8; 3]) -> Quat {
    let xyz = Vec3::from_array(r.map(|v| f32::from(v) / 127.5 - 1.0));
    let w = (1.0 - xyz.length_squared()).max(0.0).sqrt();
    Quat::from_xyzw(xyz.x, xyz.y, xyz.z, w)
}

/// Version 3: the index of the largest component (2 bits), then the other three in x, y, z, w
/// order, each a sign bit and 9 bits of `|v| / √½` (they cannot exceed √½); the largest is made
/// positive, so it is derived from the rest. The first component stored ends in the high bits.
fn pack_smallest_three(q: Quat) -> u32 {
    let v = q.to_array();
    let largest = (0..4)
        .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
        .unwrap_or(3);
    let negate = v[largest] < 0.0;
    let mut packed = largest as u32;
    for (i, &c) in v.iter().enumerate() {
        if i == largest {
            continue;
        }
        let sign = u32::from((c < 0.0) != negate);
        // Clamped: float rounding must not carry into the sign bit.
        let magnitude = ((511.0 * c.abs() / std::f32::consts::FRAC_1_SQRT_2 + 0.5) as u32).min(511);
        packed = (packed << 10) | (sign << 9) | magnitude;
    }
    packed
}

fn unpack_smallest_three(mut packed: u32) -> Quat {
    let largest = (packed >> 30) as usize;
    let mut v = [0.0f32; 4];
    let mut sum = 0.0;
    for i in (0..4).rev() {
        if i == largest {
            continue;
        }
        let magnitude = (packed & 511) as f32;
        let negative = (packed >> 9) & 1 == 1;
        packed >>= 10;
        let c = std::f32::consts::FRAC_1_SQRT_2 * magnitude / 511.0;
        v[i] = if negative { -c } else { c };
        sum += c * c;
    }
    v[largest] = (1.0 - sum).max(0.0).sqrt();
    Quat::from_array(v)
}

#[cfg(test)]
mod tests;
