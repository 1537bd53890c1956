//! The generic PLY container: header parsing and a row reader for one element (binary either
//! endianness, or ASCII) that yields each row's scalar values as `f64`. Knows no property names;
//! bounds every allocation by the bytes the file actually holds.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use crate::scene::SceneError;

/// Headers longer than this are refused (a 3DGS header is ~1.7 KB; this bounds a garbage file).
const MAX_HEADER_BYTES: usize = 1 << 20;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScalarType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl ScalarType {
    fn parse(name: &str) -> Option<ScalarType> {
        Some(match name {
            "char" | "int8" => ScalarType::I8,
            "uchar" | "uint8" => ScalarType::U8,
            "short" | "int16" => ScalarType::I16,
            "ushort" | "uint16" => ScalarType::U16,
            "int" | "int32" => ScalarType::I32,
            "uint" | "uint32" => ScalarType::U32,
            "float" | "float32" => ScalarType::F32,
            "double" | "float64" => ScalarType::F64,
            _ => return None,
        })
    }

    pub fn size(self) -> usize {
        match self {
            ScalarType::I8 | ScalarType::U8 => 1,
            ScalarType::I16 | ScalarType::U16 => 2,
            ScalarType::I32 | ScalarType::U32 | ScalarType::F32 => 4,
            ScalarType::F64 => 8,
        }
    }

    pub fn is_float(self) -> bool {
        matches!(self, ScalarType::F32 | ScalarType::F64)
    }

    fn decode(self, bytes: &[u8], big_endian: bool) -> f64 {
        macro_rules! num {
            ($t:ty) => {{
                let mut b = [0u8; std::mem::size_of::<$t>()];
                b.copy_from_slice(&bytes[..std::mem::size_of::<$t>()]);
                if big_endian {
                    f64::from(<$t>::from_be_bytes(b))
                } else {
                    f64::from(<$t>::from_le_bytes(b))
                }
            }};
        }
        match self {
            ScalarType::I8 => num!(i8),
            ScalarType::U8 => num!(u8),
            ScalarType::I16 => num!(i16),
            ScalarType::U16 => num!(u16),
            ScalarType::I32 => num!(i32),
            ScalarType::U32 => num!(u32),
            ScalarType::F32 => num!(f32),
            ScalarType::F64 => num!(f64),
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub enum PropertyKind {
    Scalar(ScalarType),
    /// `property list <count type> <item type> name` (faces); only skippable here.
    List,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Property {
    pub name: String,
    pub kind: PropertyKind,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Element {
    pub name: String,
    pub count: u64,
    pub properties: Vec<Property>,
}

impl Element {
    /// Index of a property by name.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.properties.iter().position(|p| p.name == name)
    }

    /// Index of a property every reader of this element needs; its absence is an error naming
    /// the file.
    pub fn require(&self, name: &str, path: &Path) -> Result<usize, SceneError> {
        self.find(name)
            .ok_or_else(|| SceneError::invalid(path, format!("missing required property `{name}`")))
    }

    /// Bytes per row in a binary file, `None` when a list property makes rows variable.
    fn binary_stride(&self) -> Option<usize> {
        self.properties
            .iter()
            .map(|p| match p.kind {
                PropertyKind::Scalar(t) => Some(t.size()),
                PropertyKind::List => None,
            })
            .sum()
    }

    /// The scalar type of property `index` (lists never reach a row reader).
    pub fn scalar_type(&self, index: usize) -> Option<ScalarType> {
        match self.properties.get(index)?.kind {
            PropertyKind::Scalar(t) => Some(t),
            PropertyKind::List => None,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    pub encoding: Encoding,
    pub elements: Vec<Element>,
    /// The `comment` lines' text, in order.
    pub comments: Vec<String>,
    /// Bytes of header text, `end_header` line included: where the data starts.
    pub data_offset: u64,
}

impl Header {
    /// The element called `name`; its absence is an error naming the file.
    pub fn element(&self, name: &str, path: &Path) -> Result<&Element, SceneError> {
        self.elements
            .iter()
            .find(|e| e.name == name)
            .ok_or_else(|| SceneError::invalid(path, format!("no {name} element")))
    }
}

/// Reads one header line (up to `\n`), refusing headers beyond `MAX_HEADER_BYTES`.
fn header_line(
    reader: &mut impl BufRead,
    path: &Path,
    consumed: &mut usize,
) -> Result<String, SceneError> {
    let mut line = Vec::new();
    let limit = (MAX_HEADER_BYTES - *consumed) as u64 + 1;
    let n = reader
        .take(limit)
        .read_until(b'\n', &mut line)
        .map_err(|e| SceneError::io(path, e))?;
    *consumed += n;
    if n == 0 {
        return Err(SceneError::invalid(
            path,
            "PLY header ends before end_header",
        ));
    }
    if *consumed > MAX_HEADER_BYTES {
        return Err(SceneError::invalid(
            path,
            format!("PLY header is longer than {MAX_HEADER_BYTES} bytes"),
        ));
    }
    let text =
        String::from_utf8(line).map_err(|_| SceneError::invalid(path, "PLY header is not text"))?;
    Ok(text.trim_end_matches(['\n', '\r']).to_string())
}

/// Parses the header; the reader is left at the first data byte.
pub fn read_header(reader: &mut impl BufRead, path: &Path) -> Result<Header, SceneError> {
    let mut consumed = 0;
    let bad = |msg: String| SceneError::invalid(path, msg);
    if header_line(reader, path, &mut consumed)?.trim() != "ply" {
        return Err(bad("not a PLY file (first line is not `ply`)".into()));
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut comments = Vec::new();
    loop {
        let line = header_line(reader, path, &mut consumed)?;
        let words: Vec<&str> = line.split_ascii_whitespace().collect();
        match words.as_slice() {
            ["comment", ..] => comments.push(
                line.trim_start()
                    .strip_prefix("comment")
                    .unwrap_or_default()
                    .trim()
                    .to_string(),
            ),
            [] | ["obj_info", ..] => {}
            ["end_header"] => break,
            ["format", format, version] => {
                if *version != "1.0" {
                    return Err(bad(format!("unsupported PLY version {version}")));
                }
                encoding = Some(match *format {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLittleEndian,
                    "binary_big_endian" => Encoding::BinaryBigEndian,
                    other => return Err(bad(format!("unknown PLY format `{other}`"))),
                });
            }
            ["element", name, count] => {
                let count = count
                    .parse::<u64>()
                    .map_err(|_| bad(format!("element `{name}` has a bad count `{count}`")))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", "list", count_type, item_type, name] => {
                let (Some(_), Some(_)) =
                    (ScalarType::parse(count_type), ScalarType::parse(item_type))
                else {
                    return Err(bad(format!("property list `{name}` has an unknown type")));
                };
                let element = elements
                    .last_mut()
                    .ok_or_else(|| bad(format!("property `{name}` before any element")))?;
                element.properties.push(Property {
                    name: name.to_string(),
                    kind: PropertyKind::List,
                });
            }
            ["property", ty, name] => {
                let ty = ScalarType::parse(ty)
                    .ok_or_else(|| bad(format!("property `{name}` has unknown type `{ty}`")))?;
                let element = elements
                    .last_mut()
                    .ok_or_else(|| bad(format!("property `{name}` before any element")))?;
                if element.find(name).is_some() {
                    return Err(bad(format!("property `{name}` appears twice")));
                }
                element.properties.push(Property {
                    name: name.to_string(),
                    kind: PropertyKind::Scalar(ty),
                });
            }
            _ => return Err(bad(format!("unreadable PLY header line `{line}`"))),
        }
    }
    let encoding = encoding.ok_or_else(|| bad("PLY header has no format line".into()))?;
    Ok(Header {
        encoding,
        elements,
        comments,
        data_offset: consumed as u64,
    })
}

/// Reads rows of one element of an opened PLY file, each as its scalar values in `f64`.
pub struct RowReader {
    path: PathBuf,
    reader: BufReader<std::fs::File>,
    encoding: Encoding,
    types: Vec<ScalarType>,
    stride: usize,
    /// Rows in the element.
    pub count: usize,
    next: usize,
    buf: Vec<u8>,
    line: String,
}

impl RowReader {
    /// Opens `path`, parses the header and positions the reader at the element `name`: any
    /// elements before it are skipped. Refuses a count the rest of the file cannot hold, so a
    /// caller may allocate `count` rows.
    pub fn open(path: &Path, name: &str) -> Result<(Header, RowReader), SceneError> {
        let file = crate::scene::files::open_regular(path)?;
        let file_len = file.metadata().map_err(|e| SceneError::io(path, e))?.len();
        let mut reader = BufReader::with_capacity(1 << 16, file);
        let header = read_header(&mut reader, path)?;
        let bad = |msg: String| SceneError::invalid(path, msg);
        let index = header
            .elements
            .iter()
            .position(|e| e.name == name)
            .ok_or_else(|| bad(format!("PLY file has no `{name}` element")))?;
        let element = &header.elements[index];
        let mut types = Vec::with_capacity(element.properties.len());
        for p in &element.properties {
            match p.kind {
                PropertyKind::Scalar(t) => types.push(t),
                PropertyKind::List => {
                    return Err(SceneError::unsupported(
                        path,
                        format!("list property `{}` in element `{name}`", p.name),
                    ));
                }
            }
        }
        let stride: usize = types.iter().map(|t| t.size()).sum();
        // Smallest bytes a row can take: binary = stride; ASCII = one digit and a separator each.
        let min_row = match header.encoding {
            Encoding::Ascii => 2 * types.len().max(1),
            _ => stride.max(1),
        };
        let mut skip_bytes = 0u64;
        for before in &header.elements[..index] {
            match header.encoding {
                Encoding::Ascii => skip_ascii_lines(&mut reader, path, before.count)?,
                _ => {
                    let stride = before.binary_stride().ok_or_else(|| {
                        SceneError::unsupported(
                            path,
                            format!("element `{}` with lists before `{name}`", before.name),
                        )
                    })?;
                    let bytes = (stride as u64)
                        .checked_mul(before.count)
                        .ok_or_else(|| bad(format!("element `{}` count is absurd", before.name)))?;
                    skip_bytes = skip_bytes.saturating_add(bytes);
                }
            }
        }
        if skip_bytes > 0 {
            let skipped = std::io::copy(&mut (&mut reader).take(skip_bytes), &mut std::io::sink())
                .map_err(|e| SceneError::io(path, e))?;
            if skipped < skip_bytes {
                return Err(bad("PLY data is truncated".into()));
            }
        }
        let data_len = file_len.saturating_sub(header.data_offset);
        let needed = (min_row as u64).checked_mul(element.count);
        if needed.is_none_or(|n| n > data_len) {
            return Err(bad(format!(
                "element `{name}` claims {} rows, more than the {data_len} data bytes can hold",
                element.count
            )));
        }
        let count = element.count as usize;
        let encoding = header.encoding;
        Ok((
            header,
            RowReader {
                path: path.to_path_buf(),
                reader,
                encoding,
                types,
                stride,
                count,
                next: 0,
                buf: vec![0; stride],
                line: String::new(),
            },
        ))
    }

    /// Reads the next row into `values` (one `f64` per property); `Ok(false)` after the last.
    pub fn next_row(&mut self, values: &mut Vec<f64>) -> Result<bool, SceneError> {
        if self.next >= self.count {
            return Ok(false);
        }
        let row = self.next;
        self.next += 1;
        values.clear();
        let truncated = || {
            SceneError::invalid(
                &self.path,
                format!("PLY data is truncated at row {row} of {}", self.count),
            )
        };
        match self.encoding {
            Encoding::Ascii => {
                self.line.clear();
                let n = (&mut self.reader)
                    .take(1 << 20)
                    .read_line(&mut self.line)
                    .map_err(|e| SceneError::io(&self.path, e))?;
                if n == 0 {
                    return Err(truncated());
                }
                for word in self.line.split_ascii_whitespace() {
                    let v: f64 = word.parse().map_err(|_| {
                        SceneError::invalid(
                            &self.path,
                            format!("row {row}: `{word}` is not a number"),
                        )
                    })?;
                    values.push(v);
                }
                if values.len() != self.types.len() {
                    return Err(SceneError::invalid(
                        &self.path,
                        format!(
                            "row {row} has {} values, the header declares {}",
                            values.len(),
                            self.types.len()
                        ),
                    ));
                }
            }
            Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => {
                let big = self.encoding == Encoding::BinaryBigEndian;
                self.reader.read_exact(&mut self.buf).map_err(|e| {
                    if e.kind() == std::io::ErrorKind::UnexpectedEof {
                        truncated()
                    } else {
                        SceneError::io(&self.path, e)
                    }
                })?;
                let mut offset = 0;
                for t in &self.types {
                    values.push(t.decode(&self.buf[offset..], big));
                    offset += t.size();
                }
                debug_assert_eq!(offset, self.stride);
            }
        }
        Ok(true)
    }
}

fn skip_ascii_lines(reader: &mut impl BufRead, path: &Path, lines: u64) -> Result<(), SceneError> {
    let mut line = Vec::new();
    for _ in 0..lines {
        line.clear();
        let n = reader
            .read_until(b'\n', &mut line)
            .map_err(|e| SceneError::io(path, e))?;
        if n == 0 {
            return Err(SceneError::invalid(path, "PLY data is truncated"));
        }
    }
    Ok(())
}
