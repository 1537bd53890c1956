//! COLMAP's binary sparse model (`cameras.bin`, `images.bin`, `points3D.bin`, little-endian).
//! Every count is checked against the bytes left in the file before anything is allocated, so a
//! corrupt count fails with an error instead of reserving terabytes.

use std::io::Write;
use std::path::Path;

use super::{CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint};
use crate::scene::SceneError;
use crate::scene::files::read_regular;
use crate::scene::limits::MAX_COLMAP_BYTES;

/// Reads `cameras.bin`, `images.bin` and `points3D.bin` from `dir`.
pub fn read_binary(dir: &Path) -> Result<ColmapModel, SceneError> {
    Ok(ColmapModel {
        cameras: read_cameras(&dir.join("cameras.bin"))?,
        images: read_images(&dir.join("images.bin"))?,
        points: read_points(&dir.join("points3D.bin"))?,
    })
}

/// Writes the three `.bin` files into `dir` (created if missing).
pub fn write_binary(dir: &Path, model: &ColmapModel) -> Result<(), SceneError> {
    std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;

    let mut out = Vec::new();
    put_u64(&mut out, model.cameras.len() as u64);
    for c in &model.cameras {
        if c.params.len() != c.model.param_count() {
            return Err(SceneError::invalid(
                dir.join("cameras.bin"),
                format!(
                    "camera {}: {} needs {} parameters, got {}",
                    c.id,
                    c.model.name(),
                    c.model.param_count(),
                    c.params.len()
                ),
            ));
        }
        out.extend_from_slice(&c.id.to_le_bytes());
        out.extend_from_slice(&c.model.id().to_le_bytes());
        put_u64(&mut out, c.width);
        put_u64(&mut out, c.height);
        c.params.iter().for_each(|&v| put_f64(&mut out, v));
    }
    write_file(&dir.join("cameras.bin"), &out)?;

    out.clear();
    put_u64(&mut out, model.images.len() as u64);
    for im in &model.images {
        if im.name.contains('\0') {
            return Err(SceneError::invalid(
                dir.join("images.bin"),
                format!("image {}: name contains a NUL byte", im.id),
            ));
        }
        out.extend_from_slice(&im.id.to_le_bytes());
        im.qvec.iter().for_each(|&v| put_f64(&mut out, v));
        im.tvec.iter().for_each(|&v| put_f64(&mut out, v));
        out.extend_from_slice(&im.camera_id.to_le_bytes());
        out.extend_from_slice(im.name.as_bytes());
        out.push(0);
        put_u64(&mut out, im.points2d.len() as u64);
        for &([x, y], id) in &im.points2d {
            put_f64(&mut out, x);
            put_f64(&mut out, y);
            out.extend_from_slice(&id.to_le_bytes());
        }
    }
    write_file(&dir.join("images.bin"), &out)?;

    out.clear();
    put_u64(&mut out, model.points.len() as u64);
    for p in &model.points {
        put_u64(&mut out, p.id);
        p.xyz.iter().for_each(|&v| put_f64(&mut out, v));
        out.extend_from_slice(&p.rgb);
        put_f64(&mut out, p.error);
        put_u64(&mut out, p.track.len() as u64);
        for &(image_id, point2d) in &p.track {
            out.extend_from_slice(&image_id.to_le_bytes());
            out.extend_from_slice(&point2d.to_le_bytes());
        }
    }
    write_file(&dir.join("points3D.bin"), &out)
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), SceneError> {
    let mut file = std::fs::File::create(path).map_err(|e| SceneError::io(path, e))?;
    file.write_all(bytes).map_err(|e| SceneError::io(path, e))
}

fn put_u64(out: &mut Vec<u8>, v: u64) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_f64(out: &mut Vec<u8>, v: f64) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn read_cameras(path: &Path) -> Result<Vec<ColmapCamera>, SceneError> {
    let bytes = read_regular(path, MAX_COLMAP_BYTES)?;
    let mut r = Reader::new(path, &bytes);
    // Smallest record: id, model, width, height, 3 params.
    let count = r.count("cameras", 4 + 4 + 8 + 8 + 3 * 8)?;
    let mut cameras = Vec::with_capacity(count);
    for _ in 0..count {
        let id = r.u32()?;
        let model_id = r.i32()?;
        let model = CameraModel::from_id(model_id)
            .ok_or_else(|| r.error(format!("camera {id}: unknown camera model id {model_id}")))?;
        let width = r.u64()?;
        let height = r.u64()?;
        let mut params = Vec::with_capacity(model.param_count());
        for _ in 0..model.param_count() {
            params.push(r.f64()?);
        }
        if cameras.iter().any(|c: &ColmapCamera| c.id == id) {
            return Err(r.error(format!("duplicate camera id {id}")));
        }
        cameras.push(ColmapCamera {
            id,
            model,
            width,
            height,
            params,
        });
    }
    r.finish()?;
    Ok(cameras)
}

fn read_images(path: &Path) -> Result<Vec<ColmapImage>, SceneError> {
    let bytes = read_regular(path, MAX_COLMAP_BYTES)?;
    let mut r = Reader::new(path, &bytes);
    // Smallest record: id, qvec, tvec, camera id, 1-byte name + NUL, point count.
    let count = r.count("images", 4 + 7 * 8 + 4 + 2 + 8)?;
    let mut images = Vec::with_capacity(count);
    let mut ids = std::collections::HashSet::with_capacity(count);
    for _ in 0..count {
        let id = r.u32()?;
        let qvec = [r.f64()?, r.f64()?, r.f64()?, r.f64()?];
        let tvec = [r.f64()?, r.f64()?, r.f64()?];
        let camera_id = r.u32()?;
        let name = r.c_string()?;
        let n = r.count(&format!("keypoints of image {id}"), 8 + 8 + 8)?;
        let mut points2d = Vec::with_capacity(n);
        for _ in 0..n {
            let xy = [r.f64()?, r.f64()?];
            points2d.push((xy, r.i64()?));
        }
        if !ids.insert(id) {
            return Err(r.error(format!("duplicate image id {id}")));
        }
        images.push(ColmapImage {
            id,
            qvec,
            tvec,
            camera_id,
            name,
            points2d,
        });
    }
    r.finish()?;
    Ok(images)
}

fn read_points(path: &Path) -> Result<Vec<ColmapPoint>, SceneError> {
    let bytes = read_regular(path, MAX_COLMAP_BYTES)?;
    let mut r = Reader::new(path, &bytes);
    // Smallest record: id, xyz, rgb, error, track length.
    let count = r.count("points", 8 + 3 * 8 + 3 + 8 + 8)?;
    let mut points = Vec::with_capacity(count);
    for _ in 0..count {
        let id = r.u64()?;
        let xyz = [r.f64()?, r.f64()?, r.f64()?];
        let rgb = [r.u8()?, r.u8()?, r.u8()?];
        let error = r.f64()?;
        let n = r.count(&format!("track of point {id}"), 4 + 4)?;
        let mut track = Vec::with_capacity(n);
        for _ in 0..n {
            track.push((r.u32()?, r.u32()?));
        }
        points.push(ColmapPoint {
            id,
            xyz,
            rgb,
            error,
            track,
        });
    }
    r.finish()?;
    Ok(points)
}

/// A bounds-checked little-endian cursor that names its file in every error.
struct Reader<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn new(path: &'a Path, bytes: &'a [u8]) -> Self {
        Reader {
            path,
            bytes,
            pos: 0,
        }
    }

    fn error(&self, message: String) -> SceneError {
        SceneError::invalid(self.path, format!("{message} (at byte {})", self.pos))
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N], SceneError> {
        let end = self.pos.checked_add(N).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(self.error(format!(
                "truncated: needs {N} more bytes, file has {}",
                self.bytes.len()
            )));
        };
        let mut out = [0u8; N];
        out.copy_from_slice(&self.bytes[self.pos..end]);
        self.pos = end;
        Ok(out)
    }

    fn u8(&mut self) -> Result<u8, SceneError> {
        Ok(self.take::<1>()?[0])
    }
    fn u32(&mut self) -> Result<u32, SceneError> {
        Ok(u32::from_le_bytes(self.take()?))
    }
    fn i32(&mut self) -> Result<i32, SceneError> {
        Ok(i32::from_le_bytes(self.take()?))
    }
    fn u64(&mut self) -> Result<u64, SceneError> {
        Ok(u64::from_le_bytes(self.take()?))
    }
    fn i64(&mut self) -> Result<i64, SceneError> {
        Ok(i64::from_le_bytes(self.take()?))
    }
    fn f64(&mut self) -> Result<f64, SceneError> {
        Ok(f64::from_le_bytes(self.take()?))
    }

    /// A u64 count of records of at least `min_record_bytes` each, refused when the rest of the
    /// file cannot hold that many: this bounds every allocation by the file size.
    fn count(&mut self, what: &str, min_record_bytes: usize) -> Result<usize, SceneError> {
        let n = self.u64()?;
        let left = (self.bytes.len() - self.pos) as u64;
        if n > left / min_record_bytes as u64 {
            return Err(self.error(format!(
                "{what}: count {n} needs at least {} bytes, only {left} left",
                n.saturating_mul(min_record_bytes as u64)
            )));
        }
        Ok(n as usize)
    }

    /// A NUL-terminated UTF-8 name.
    fn c_string(&mut self) -> Result<String, SceneError> {
        let rest = &self.bytes[self.pos..];
        let Some(len) = rest.iter().position(|&b| b == 0) else {
            return Err(self.error("truncated: image name has no terminating NUL".into()));
        };
        let name = std::str::from_utf8(&rest[..len])
            .map_err(|_| self.error("image name is not UTF-8".into()))?
            .to_owned();
        if name.is_empty() {
            return Err(self.error("empty image name".into()));
        }
        self.pos += len + 1;
        Ok(name)
    }

    fn finish(&self) -> Result<(), SceneError> {
        if self.pos != self.bytes.len() {
            return Err(self.error(format!(
                "{} unexpected trailing bytes",
                self.bytes.len() - self.pos
            )));
        }
        Ok(())
    }
}
