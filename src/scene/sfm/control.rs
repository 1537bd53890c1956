//! Surveyed control points: a plain CSV of points with their surveyed position and where they
//! appear in the photos, triangulated in the SfM model and fitted by a similarity (per-point
//! residuals kept), some held out as check points to measure the fit on points it did not use.
//! Control points win over GPS: their georeference replaces one from GPS.
//!
//! The format (one row per observation of a point in a photo; `#` starts a comment line):
//!
//! ```text
//! name,latitude,longitude,height,image,pixel_x,pixel_y,check
//! CP1,55.698101,13.195342,41.20,01.jpg,512.4,300.1,
//! CP1,55.698101,13.195342,41.20,02.jpg,488.0,310.7,
//! CP4,55.698300,13.195100,40.90,05.jpg,100.5,220.0,1
//! ```
//!
//! or `name,x,y,z,image,pixel_x,pixel_y,check` for points in a local metric frame of their own
//! (a site grid; metres). Degrees are WGS84, height in metres as surveyed. Pixels are in the
//! photo as stored, COLMAP's convention: (0, 0) is the top-left corner of the top-left pixel.
//! `check` (optional column): `1`, `yes` or `true` holds the point out of the fit.

use std::path::{Path, PathBuf};

use glam::{DMat3, DQuat, DVec3};
use serde::Serialize;

use crate::scene::colmap::ColmapModel;
use crate::scene::files::read_regular;
use crate::scene::sfm::SfmError;
use crate::scene::sfm::georef::{GeorefSource, Georeference, geodetic_to_enu};
use crate::scene::similarity::{spread, umeyama};
use crate::scene::undistort::distort;

/// How the control points' positions are given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ControlFrame {
    /// Latitude, longitude (degrees), height (metres).
    Geodetic,
    /// x, y, z in metres in a frame of the survey's own.
    Local,
}

/// One surveyed point and its observations.
#[derive(Clone, Debug, PartialEq)]
pub struct ControlPoint {
    pub name: String,
    /// As written: (latitude, longitude, height) or (x, y, z).
    pub surveyed: DVec3,
    /// (image name, pixel) per photo it appears in.
    pub observations: Vec<(String, [f64; 2])>,
    /// Held out of the fit.
    pub check: bool,
}

/// One point's outcome.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PointResidual {
    pub name: String,
    pub check: bool,
    /// Distance in metres between the surveyed position and the triangulated one mapped
    /// through the fit.
    pub residual_m: f64,
}

/// The fit to control points.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ControlFit {
    pub georeference: Georeference,
    pub points: Vec<PointResidual>,
    /// RMS residual of the check points (metres), `None` without check points.
    pub check_rms_m: Option<f64>,
}

fn line_error(path: &Path, line: usize, message: impl std::fmt::Display) -> SfmError {
    SfmError::input(path, format!("line {line}: {message}"))
}

/// Reads a control-point CSV (see the module comment).
pub fn read_control_points(path: &Path) -> Result<(ControlFrame, Vec<ControlPoint>), SfmError> {
    let bytes = read_regular(path, 16 << 20)?;
    let text = String::from_utf8(bytes)
        .map_err(|_| SfmError::input(path, "not UTF-8 text (a CSV of control points)"))?;
    let mut rows = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let (header_line, header) = rows
        .next()
        .ok_or_else(|| SfmError::input(path, "empty: expected a header line"))?;
    let columns: Vec<String> = header
        .split(',')
        .map(|c| c.trim().to_ascii_lowercase())
        .collect();
    let frame = match columns.get(1..4) {
        Some([a, b, c])
            if (a.as_str(), b.as_str(), c.as_str()) == ("latitude", "longitude", "height") =>
        {
            ControlFrame::Geodetic
        }
        Some([a, b, c]) if (a.as_str(), b.as_str(), c.as_str()) == ("x", "y", "z") => {
            ControlFrame::Local
        }
        _ => {
            return Err(line_error(
                path,
                header_line,
                "expected the header name,latitude,longitude,height,image,pixel_x,pixel_y[,check] \
                 or name,x,y,z,image,pixel_x,pixel_y[,check]",
            ));
        }
    };
    let mut points: Vec<ControlPoint> = Vec::new();
    for (line, row) in rows {
        let fields: Vec<&str> = row.split(',').map(str::trim).collect();
        if fields.len() < 7 {
            return Err(line_error(
                path,
                line,
                format!("{} fields, expected at least 7", fields.len()),
            ));
        }
        let number = |i: usize| -> Result<f64, SfmError> {
            fields[i]
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    line_error(
                        path,
                        line,
                        format!("{}: {:?} is not a number", columns[i], fields[i]),
                    )
                })
        };
        let surveyed = DVec3::new(number(1)?, number(2)?, number(3)?);
        if frame == ControlFrame::Geodetic
            && !(surveyed.x.abs() <= 90.0 && surveyed.y.abs() <= 180.0)
        {
            return Err(line_error(path, line, "latitude or longitude out of range"));
        }
        let pixel = [number(5)?, number(6)?];
        let check = fields
            .get(7)
            .is_some_and(|c| matches!(c.to_ascii_lowercase().as_str(), "1" | "yes" | "true"));
        let (name, image) = (fields[0].to_owned(), fields[4].to_owned());
        if name.is_empty() || image.is_empty() {
            return Err(line_error(
                path,
                line,
                "a point name and an image name are needed",
            ));
        }
        match points.iter_mut().find(|p| p.name == name) {
            Some(p) => {
                if p.surveyed.distance(surveyed) > 1e-9 {
                    return Err(line_error(
                        path,
                        line,
                        format!("point {name} has another position than on its earlier rows"),
                    ));
                }
                p.check |= check;
                p.observations.push((image, pixel));
            }
            None => points.push(ControlPoint {
                name,
                surveyed,
                observations: vec![(image, pixel)],
                check,
            }),
        }
    }
    Ok((frame, points))
}

/// A registered camera: world-to-camera rotation and translation, and its lens.
struct PosedCamera {
    rotation: DQuat,
    translation: DVec3,
    /// fx, fy, cx, cy, k1, k2, p1, p2.
    lens: [f64; 8],
}

impl PosedCamera {
    /// The viewing ray of a pixel: centre and unit direction in the model frame.
    fn ray(&self, pixel: [f64; 2]) -> (DVec3, DVec3) {
        let [fx, fy, cx, cy, k1, k2, p1, p2] = self.lens;
        let distorted = ((pixel[0] - cx) / fx, (pixel[1] - cy) / fy);
        // Invert the lens by fixed-point iteration (converges for the mild distortion COLMAP's
        // radial models describe).
        let mut u = distorted;
        for _ in 0..50 {
            let d = distort(u.0, u.1, k1, k2, p1, p2);
            u = (u.0 + distorted.0 - d.0, u.1 + distorted.1 - d.1);
        }
        let inverse = self.rotation.inverse();
        let centre = -(inverse * self.translation);
        (centre, (inverse * DVec3::new(u.0, u.1, 1.0)).normalize())
    }

    fn depth(&self, p: DVec3) -> f64 {
        (self.rotation * p + self.translation).z
    }
}

/// The cameras of `model` by image name.
fn posed_cameras(
    model: &ColmapModel,
    model_path: &Path,
) -> Result<Vec<(String, PosedCamera)>, SfmError> {
    let mut out = Vec::new();
    for image in &model.images {
        let Some(camera) = model.cameras.iter().find(|c| c.id == image.camera_id) else {
            continue;
        };
        let (k, distortion) = camera.to_pinhole(model_path)?;
        let lens = match distortion {
            Some(d) => [d.fx, d.fy, d.cx, d.cy, d.k1, d.k2, d.p1, d.p2].map(f64::from),
            None => [k.fx, k.fy, k.cx, k.cy, 0.0, 0.0, 0.0, 0.0].map(f64::from),
        };
        let Some((q, t)) = image.pose() else { continue };
        out.push((
            image.name.clone(),
            PosedCamera {
                rotation: q.as_dquat(),
                translation: t.as_dvec3(),
                lens,
            },
        ));
    }
    Ok(out)
}

/// The point closest to every ray (least squares), refused when it is behind a camera that sees
/// it or the rays are parallel.
fn triangulate(
    point: &ControlPoint,
    cameras: &[(String, PosedCamera)],
    csv: &Path,
) -> Result<DVec3, SfmError> {
    let mut a = DMat3::ZERO;
    let mut b = DVec3::ZERO;
    let mut seen = Vec::new();
    for (image, pixel) in &point.observations {
        let Some((_, camera)) = cameras.iter().find(|(n, _)| n == image) else {
            let names: Vec<&str> = cameras.iter().take(3).map(|(n, _)| n.as_str()).collect();
            return Err(SfmError::input(
                csv,
                format!(
                    "point {}: image {image:?} is not a registered photo of the model (they are \
                     named like {})",
                    point.name,
                    names.join(", ")
                ),
            ));
        };
        let (c, d) = camera.ray(*pixel);
        let m = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += m;
        b += m * c;
        seen.push((image, camera));
    }
    if seen.len() < 2 {
        return Err(SfmError::input(
            csv,
            format!(
                "point {}: seen in {} photo(s), at least 2 are needed to place it",
                point.name,
                seen.len()
            ),
        ));
    }
    if !(a.determinant().abs() > 1e-12) {
        return Err(SfmError::input(
            csv,
            format!(
                "point {}: its rays are parallel (photos taken from one place)",
                point.name
            ),
        ));
    }
    let x = a.inverse() * b;
    for (image, camera) in seen {
        if !(camera.depth(x) > 0.0) {
            return Err(SfmError::input(
                csv,
                format!(
                    "point {}: its rays meet behind the camera of {image} (a wrong pixel or \
                     image name)",
                    point.name
                ),
            ));
        }
    }
    Ok(x)
}

/// Fits the model to the control points: the non-check points give the similarity (at least
/// 3), every point gets its residual in metres.
pub fn fit_control_points(
    model: &ColmapModel,
    model_path: &Path,
    csv: &Path,
) -> Result<ControlFit, SfmError> {
    let (frame, points) = read_control_points(csv)?;
    let cameras = posed_cameras(model, model_path)?;
    let fit_count = points.iter().filter(|p| !p.check).count();
    if fit_count < 3 {
        return Err(SfmError::input(
            csv,
            format!(
                "{fit_count} control point(s) for the fit (besides {} check point(s)): a \
                 similarity needs at least 3",
                points.len() - fit_count
            ),
        ));
    }
    let mut model_points = Vec::new();
    for p in &points {
        model_points.push(triangulate(p, &cameras, csv)?);
    }
    let n = points.len() as f64;
    let origin = match frame {
        ControlFrame::Geodetic => points.iter().map(|p| p.surveyed).sum::<DVec3>() / n,
        ControlFrame::Local => DVec3::ZERO,
    };
    let metric: Vec<DVec3> = points
        .iter()
        .map(|p| match frame {
            ControlFrame::Geodetic => geodetic_to_enu(
                (p.surveyed.x, p.surveyed.y, p.surveyed.z),
                (origin.x, origin.y, origin.z),
            ),
            ControlFrame::Local => p.surveyed,
        })
        .collect();
    let fit_indices: Vec<usize> = (0..points.len()).filter(|&i| !points[i].check).collect();
    let from: Vec<DVec3> = fit_indices.iter().map(|&i| model_points[i]).collect();
    let to: Vec<DVec3> = fit_indices.iter().map(|&i| metric[i]).collect();
    let similarity = umeyama(&from, &to).ok_or_else(|| {
        SfmError::input(
            csv,
            "the control points used for the fit are degenerate (all at one place)",
        )
    })?;
    let residuals: Vec<PointResidual> = points
        .iter()
        .enumerate()
        .map(|(i, p)| PointResidual {
            name: p.name.clone(),
            check: p.check,
            residual_m: similarity.apply(model_points[i]).distance(metric[i]),
        })
        .collect();
    let rms = |check: bool| -> Option<f64> {
        let r: Vec<f64> = residuals
            .iter()
            .filter(|r| r.check == check)
            .map(|r| r.residual_m)
            .collect();
        (!r.is_empty()).then(|| (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt())
    };
    let rms_m = rms(false).unwrap_or(0.0);
    let baseline_m = spread(&to);
    Ok(ControlFit {
        georeference: Georeference {
            source: match frame {
                ControlFrame::Geodetic => GeorefSource::ControlPoints,
                ControlFrame::Local => GeorefSource::LocalControlPoints,
            },
            latitude: origin.x,
            longitude: origin.y,
            altitude: origin.z,
            similarity,
            rms_m,
            used: fit_indices
                .iter()
                .map(|&i| points[i].name.clone())
                .collect(),
            rejected: Vec::new(),
            baseline_m,
            scale_uncertainty: rms_m / (baseline_m.max(1e-9) * (fit_count as f64).sqrt()),
            model_doubt: None,
        },
        check_rms_m: rms(true),
        points: residuals,
    })
}

/// Where a dataset keeps its control-point fit (`ControlFit` as JSON).
pub const CONTROL_FIT_FILE: &str = "control_points.json";

/// The dataset's COLMAP model folder (`sparse/0`).
pub fn model_dir(dataset: &Path) -> PathBuf {
    dataset.join("sparse").join("0")
}
