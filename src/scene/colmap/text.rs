//! COLMAP's text sparse model (`cameras.txt`, `images.txt`, `points3D.txt`). Numbers are written
//! in Rust's shortest round-trip form, so binary → text → binary reproduces every `f64` exactly.
//! Every malformed line is an error naming the file and the line number.

use std::fmt::Write as _;
use std::path::Path;
use std::str::FromStr;

use super::{CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint};
use crate::scene::SceneError;
use crate::scene::files::read_regular;
use crate::scene::limits::MAX_COLMAP_BYTES;

/// Reads `cameras.txt`, `images.txt` and `points3D.txt` from `dir`.
pub fn read_text(dir: &Path) -> Result<ColmapModel, SceneError> {
    Ok(ColmapModel {
        cameras: read_cameras(&dir.join("cameras.txt"))?,
        images: read_images(&dir.join("images.txt"))?,
        points: read_points(&dir.join("points3D.txt"))?,
    })
}

/// Writes the three `.txt` files into `dir` (created if missing), with COLMAP's header comments.
pub fn write_text(dir: &Path, model: &ColmapModel) -> Result<(), SceneError> {
    std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;

    let path = dir.join("cameras.txt");
    let mut s = String::new();
    s.push_str("# Camera list with one line of data per camera:\n");
    s.push_str("#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n");
    let _ = writeln!(s, "# Number of cameras: {}", model.cameras.len());
    for c in &model.cameras {
        if c.params.len() != c.model.param_count() {
            return Err(SceneError::invalid(
                &path,
                format!(
                    "camera {}: {} needs {} parameters, got {}",
                    c.id,
                    c.model.name(),
                    c.model.param_count(),
                    c.params.len()
                ),
            ));
        }
        let _ = write!(s, "{} {} {} {}", c.id, c.model.name(), c.width, c.height);
        c.params.iter().for_each(|v| {
            let _ = write!(s, " {v:?}");
        });
        s.push('\n');
    }
    write_file(&path, &s)?;

    let path = dir.join("images.txt");
    s.clear();
    s.push_str("# Image list with two lines of data per image:\n");
    s.push_str("#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n");
    s.push_str("#   POINTS2D[] as (X, Y, POINT3D_ID)\n");
    let _ = writeln!(s, "# Number of images: {}", model.images.len());
    for im in &model.images {
        if im.name.is_empty() || im.name.trim() != im.name || im.name.contains(['\n', '\r']) {
            return Err(SceneError::invalid(
                &path,
                format!(
                    "image {}: name {:?} cannot be written to a text model",
                    im.id, im.name
                ),
            ));
        }
        let [qw, qx, qy, qz] = im.qvec;
        let [tx, ty, tz] = im.tvec;
        let _ = writeln!(
            s,
            "{} {qw:?} {qx:?} {qy:?} {qz:?} {tx:?} {ty:?} {tz:?} {} {}",
            im.id, im.camera_id, im.name
        );
        for (i, ([x, y], id)) in im.points2d.iter().enumerate() {
            let sep = if i == 0 { "" } else { " " };
            let _ = write!(s, "{sep}{x:?} {y:?} {id}");
        }
        s.push('\n');
    }
    write_file(&path, &s)?;

    let path = dir.join("points3D.txt");
    s.clear();
    s.push_str("# 3D point list with one line of data per point:\n");
    s.push_str("#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n");
    let _ = writeln!(s, "# Number of points: {}", model.points.len());
    for p in &model.points {
        let [x, y, z] = p.xyz;
        let [r, g, b] = p.rgb;
        let _ = write!(s, "{} {x:?} {y:?} {z:?} {r} {g} {b} {:?}", p.id, p.error);
        for (image_id, point2d) in &p.track {
            let _ = write!(s, " {image_id} {point2d}");
        }
        s.push('\n');
    }
    write_file(&path, &s)
}

fn write_file(path: &Path, text: &str) -> Result<(), SceneError> {
    std::fs::write(path, text).map_err(|e| SceneError::io(path, e))
}

fn read_file(path: &Path) -> Result<String, SceneError> {
    let bytes = read_regular(path, MAX_COLMAP_BYTES)?;
    String::from_utf8(bytes).map_err(|e| {
        SceneError::invalid(
            path,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        )
    })
}

/// Data lines with their 1-based line numbers: comments and blank lines skipped.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

/// Parses one whitespace-separated field, naming the line and the field on failure.
fn field<T: FromStr>(
    path: &Path,
    line_no: usize,
    what: &str,
    token: Option<&str>,
) -> Result<T, SceneError> {
    let Some(token) = token else {
        return Err(SceneError::invalid(
            path,
            format!("line {line_no}: missing {what}"),
        ));
    };
    token.parse().map_err(|_| {
        SceneError::invalid(
            path,
            format!("line {line_no}: {what} {token:?} is not a valid number"),
        )
    })
}

fn read_cameras(path: &Path) -> Result<Vec<ColmapCamera>, SceneError> {
    let text = read_file(path)?;
    let mut cameras: Vec<ColmapCamera> = Vec::new();
    for (line_no, line) in data_lines(&text) {
        let mut tokens = line.split_ascii_whitespace();
        let id: u32 = field(path, line_no, "camera id", tokens.next())?;
        let model_name = tokens.next().unwrap_or("");
        let model = CameraModel::from_name(model_name).ok_or_else(|| {
            SceneError::invalid(
                path,
                format!("line {line_no}: unknown camera model {model_name:?}"),
            )
        })?;
        let width = field(path, line_no, "width", tokens.next())?;
        let height = field(path, line_no, "height", tokens.next())?;
        let params = tokens
            .map(|t| field(path, line_no, "camera parameter", Some(t)))
            .collect::<Result<Vec<f64>, _>>()?;
        if params.len() != model.param_count() {
            return Err(SceneError::invalid(
                path,
                format!(
                    "line {line_no}: {} needs {} parameters, found {}",
                    model.name(),
                    model.param_count(),
                    params.len()
                ),
            ));
        }
        if cameras.iter().any(|c| c.id == id) {
            return Err(SceneError::invalid(
                path,
                format!("line {line_no}: duplicate camera id {id}"),
            ));
        }
        cameras.push(ColmapCamera {
            id,
            model,
            width,
            height,
            params,
        });
    }
    Ok(cameras)
}

fn read_images(path: &Path) -> Result<Vec<ColmapImage>, SceneError> {
    let text = read_file(path)?;
    let mut images = Vec::new();
    let mut ids = std::collections::HashSet::new();
    // Two lines per image; the keypoint line directly follows and may be empty, so it is taken
    // without skipping blanks (as COLMAP's own reader does).
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    while let Some((line_no, line)) = lines.next() {
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut tokens = line.split_ascii_whitespace();
        let id: u32 = field(path, line_no, "image id", tokens.next())?;
        let mut numbers = [0.0f64; 7];
        for (k, v) in numbers.iter_mut().enumerate() {
            let what = ["QW", "QX", "QY", "QZ", "TX", "TY", "TZ"][k];
            *v = field(path, line_no, what, tokens.next())?;
        }
        let camera_id: u32 = field(path, line_no, "camera id", tokens.next())?;
        // The name is the rest of the line, so names with spaces survive.
        let Some(first) = tokens.next() else {
            return Err(SceneError::invalid(
                path,
                format!("line {line_no}: missing image name"),
            ));
        };
        let offset = first.as_ptr() as usize - line.as_ptr() as usize;
        let name = line[offset..].to_owned();
        if !ids.insert(id) {
            return Err(SceneError::invalid(
                path,
                format!("line {line_no}: duplicate image id {id}"),
            ));
        }

        let mut points2d = Vec::new();
        if let Some((kp_line_no, kp_line)) = lines.next() {
            let tokens: Vec<&str> = kp_line.split_ascii_whitespace().collect();
            if !tokens.len().is_multiple_of(3) {
                return Err(SceneError::invalid(
                    path,
                    format!(
                        "line {kp_line_no}: keypoints of image {id} need X Y POINT3D_ID triples, \
                         found {} values",
                        tokens.len()
                    ),
                ));
            }
            points2d.reserve(tokens.len() / 3);
            for t in tokens.chunks_exact(3) {
                let x = field(path, kp_line_no, "keypoint x", Some(t[0]))?;
                let y = field(path, kp_line_no, "keypoint y", Some(t[1]))?;
                let point_id = field(path, kp_line_no, "POINT3D_ID", Some(t[2]))?;
                points2d.push(([x, y], point_id));
            }
        }
        let [qw, qx, qy, qz, tx, ty, tz] = numbers;
        images.push(ColmapImage {
            id,
            qvec: [qw, qx, qy, qz],
            tvec: [tx, ty, tz],
            camera_id,
            name,
            points2d,
        });
    }
    Ok(images)
}

fn read_points(path: &Path) -> Result<Vec<ColmapPoint>, SceneError> {
    let text = read_file(path)?;
    let mut points = Vec::new();
    for (line_no, line) in data_lines(&text) {
        let mut tokens = line.split_ascii_whitespace();
        let id = field(path, line_no, "point id", tokens.next())?;
        let xyz = [
            field(path, line_no, "X", tokens.next())?,
            field(path, line_no, "Y", tokens.next())?,
            field(path, line_no, "Z", tokens.next())?,
        ];
        let rgb = [
            field(path, line_no, "R (0-255)", tokens.next())?,
            field(path, line_no, "G (0-255)", tokens.next())?,
            field(path, line_no, "B (0-255)", tokens.next())?,
        ];
        let error = field(path, line_no, "ERROR", tokens.next())?;
        let rest: Vec<&str> = tokens.collect();
        if !rest.len().is_multiple_of(2) {
            return Err(SceneError::invalid(
                path,
                format!("line {line_no}: track needs IMAGE_ID POINT2D_IDX pairs"),
            ));
        }
        let track = rest
            .chunks_exact(2)
            .map(|t| -> Result<(u32, u32), SceneError> {
                Ok((
                    field(path, line_no, "track IMAGE_ID", Some(t[0]))?,
                    field(path, line_no, "track POINT2D_IDX", Some(t[1]))?,
                ))
            })
            .collect::<Result<Vec<_>, _>>()?;
        points.push(ColmapPoint {
            id,
            xyz,
            rgb,
            error,
            track,
        });
    }
    Ok(points)
}
