//! The fuzz harness's mutations: byte-level damage for any file, header lies for PNG, JPEG and
//! PLY, and token and line edits for text formats. Each returns what it did, so a finding can
//! be read and rerun. Knows no reader.

/// Whether a file is mutated as bytes only or also as text (tokens and lines).
#[derive(Clone, Copy, PartialEq)]
pub enum Content {
    Binary,
    Text,
}

/// Replacements for a text token: huge, non-finite, negative, empty and wrong-typed values.
pub const TOKENS: &[&str] = &[
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
pub fn lie_bytes(rng: &mut fastrand::Rng) -> (Vec<u8>, String) {
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
pub fn crc32(bytes: &[u8]) -> u32 {
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
pub const SIZE_LIES: &[u32] = &[0, 1, 7, 65_535, 100_000, 1 << 20, 0x7fff_ffff, u32::MAX];

/// A header lie about the image size: PNG IHDR (checksum fixed) or JPEG SOF; None when the bytes
/// are neither.
pub fn image_size_lie(bytes: &mut [u8], rng: &mut fastrand::Rng) -> Option<String> {
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
pub fn tokens(bytes: &[u8]) -> Vec<(usize, usize)> {
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
pub fn lines(bytes: &[u8]) -> Vec<(usize, usize)> {
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
pub fn ply_header_lie(bytes: &mut Vec<u8>, rng: &mut fastrand::Rng) -> Option<String> {
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
pub fn mutate(
    bytes: &mut Vec<u8>,
    content: Content,
    rng: &mut fastrand::Rng,
    log: &mut Vec<String>,
) {
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
