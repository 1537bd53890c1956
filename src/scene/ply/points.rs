//! Coloured point clouds (`points.ply` of nerfstudio, COLMAP's exported `points3D.ply`) to and
//! from PLY: `x y z` (float or double) and optional `red green blue` (uchar; floats are taken
//! as 0..1). Not for splats; refuses (or skips, for a dataset to warn about) NaN/Inf and absurd
//! positions, and refuses empty clouds.

use std::io::Write;
use std::path::Path;

use glam::Vec3;

use super::header::RowReader;
use crate::scene::atomic::write_atomic;
use crate::scene::limits::{MAX_POINT_COORDINATE, is_usable_position};
use crate::scene::{PointCloud, SceneError};

/// Grey given to points of a file without colours (the 3DGS random-init default colour).
const DEFAULT_GREY: [u8; 3] = [128, 128, 128];

/// Reads a point cloud; a file without `red green blue` gets grey points. Zero points, and a
/// position that is not finite or beyond `limits::MAX_POINT_COORDINATE`, are errors naming the
/// vertex: a points file exists to initialise splats.
pub fn read_point_cloud(path: &Path) -> Result<PointCloud, SceneError> {
    read_cloud(path, Unusable::Refuse).map(|(cloud, _)| cloud)
}

/// [`read_point_cloud`] that skips the vertices whose position cannot seed a Gaussian (not
/// finite, or beyond `limits::MAX_POINT_COORDINATE`) and returns their indices, for the dataset
/// to warn about. The cloud may come back empty when every vertex was skipped.
pub fn read_point_cloud_skipping(path: &Path) -> Result<(PointCloud, Vec<usize>), SceneError> {
    read_cloud(path, Unusable::Skip)
}

#[derive(Clone, Copy, PartialEq)]
enum Unusable {
    Refuse,
    Skip,
}

fn read_cloud(path: &Path, unusable: Unusable) -> Result<(PointCloud, Vec<usize>), SceneError> {
    let (header, mut rows) = RowReader::open(path, "vertex")?;
    let bad = |msg: String| SceneError::invalid(path, msg);
    let vertex = header.element("vertex", path)?;
    let require = |name: &str| vertex.require(name, path);
    let xyz = [require("x")?, require("y")?, require("z")?];
    let rgb = match (
        vertex.find("red"),
        vertex.find("green"),
        vertex.find("blue"),
    ) {
        (Some(r), Some(g), Some(b)) => Some([r, g, b]),
        _ => None,
    };
    // Float colours are 0..1 (Open3D writes them so); integer colours are 0..255.
    let float_colour = rgb.is_some_and(|i| {
        i.iter()
            .any(|&p| vertex.scalar_type(p).is_some_and(|t| t.is_float()))
    });
    if rows.count == 0 {
        return Err(bad("point cloud has no points".into()));
    }
    let mut cloud = PointCloud {
        positions: Vec::with_capacity(rows.count),
        colours: Vec::with_capacity(rows.count),
    };
    let mut skipped = Vec::new();
    let mut values = Vec::with_capacity(vertex.properties.len());
    let mut index = 0usize;
    while rows.next_row(&mut values)? {
        let position = xyz.map(|i| values[i]);
        if !is_usable_position(position) {
            if unusable == Unusable::Refuse {
                return Err(bad(format!(
                    "vertex {index}: position {position:?} is not finite or beyond \
                     ±{MAX_POINT_COORDINATE:e}"
                )));
            }
            skipped.push(index);
            index += 1;
            continue;
        }
        let colour = match rgb {
            Some(i) => i.map(|i| {
                let v = if float_colour {
                    values[i] * 255.0
                } else {
                    values[i]
                };
                // `clamp` maps NaN to NaN, and `as u8` maps NaN to 0: never a panic.
                v.round().clamp(0.0, 255.0) as u8
            }),
            None => DEFAULT_GREY,
        };
        cloud
            .positions
            .push(Vec3::from_array(position.map(|v| v as f32)));
        cloud.colours.push(colour);
        index += 1;
    }
    Ok((cloud, skipped))
}

/// Writes `float x y z, uchar red green blue`, binary little-endian (the nerfstudio layout).
pub fn write_point_cloud(path: &Path, points: &PointCloud) -> Result<(), SceneError> {
    if points.positions.len() != points.colours.len() {
        return Err(SceneError::invalid(
            path,
            format!(
                "cannot save {} positions with {} colours",
                points.positions.len(),
                points.colours.len()
            ),
        ));
    }
    write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\nelement vertex {}\n\
             property float x\nproperty float y\nproperty float z\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
            points.len()
        )?;
        for (p, c) in points.positions.iter().zip(&points.colours) {
            for v in p.to_array() {
                w.write_all(&v.to_le_bytes())?;
            }
            w.write_all(c)?;
        }
        Ok(())
    })
}
