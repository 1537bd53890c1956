//! LabelMe JSON, one file per image: `imagePath`, `imageWidth`, `imageHeight` and `shapes`, each
//! a `label`, `points` `[[x, y], …]` in pixels and a `shape_type`: `polygon` (the default when
//! absent), `rectangle` (two opposite corners) or `circle` (the centre, then a point on the
//! circle). Lines and points have no area and are refused by name. Shapes fill by the pixel-centre
//! rule of `polygon` (LabelMe's own PIL drawing also takes pixels the outline touches; see
//! docs/MASKS.md).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::scene::mask_import::polygon::{fill_polygon, vertex_outside};
use crate::scene::mask_import::{
    AnnotatedImage, Annotations, ClassMapping, UnknownCategories, check_size, read_json,
};
use crate::scene::{Mask, SceneError};

#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct LabelMeFile {
    image_path: String,
    image_width: i64,
    image_height: i64,
    #[serde(default)]
    shapes: Vec<LabelMeShape>,
}

#[derive(Deserialize)]
struct LabelMeShape {
    label: String,
    points: Vec<[f64; 2]>,
    #[serde(default)]
    shape_type: Option<String>,
}

/// Reads LabelMe files (one per image) into one set of annotations. Each image gets a mask (empty
/// when it has none of it) for every class any of the files' labels maps to. Refused, naming the
/// file and the shape: malformed JSON, a label without a class (unless `mapping.unknown` skips
/// it), a vertex outside the image, a shape without an area.
pub fn read_labelme_files(
    paths: &[PathBuf],
    mapping: &ClassMapping,
) -> Result<Annotations, SceneError> {
    let mut images = Vec::with_capacity(paths.len());
    let mut skipped = BTreeMap::new();
    for path in paths {
        images.push(read_one(path, mapping, &mut skipped)?);
    }
    let classes = ClassMapping::distinct(images.iter().flat_map(|i| i.masks.keys()));
    for image in &mut images {
        for &class in &classes {
            let (w, h) = image.size;
            image
                .masks
                .entry(class)
                .or_insert_with(|| Mask::empty(w, h));
        }
    }
    Ok(Annotations {
        source: paths.first().cloned().unwrap_or_default(),
        images,
        skipped,
    })
}

fn read_one(
    path: &Path,
    mapping: &ClassMapping,
    skipped: &mut BTreeMap<String, usize>,
) -> Result<AnnotatedImage, SceneError> {
    let file: LabelMeFile = read_json(path, "LabelMe")?;
    let size = check_size(path, &file.image_path, file.image_width, file.image_height)?;
    let mut image = AnnotatedImage::empty(path, file.image_path.clone(), size, &[]);
    for (k, shape) in file.shapes.iter().enumerate() {
        let what = format!("shape {} ({:?})", k + 1, shape.label);
        let invalid = |m: String| SceneError::invalid(path, format!("{what}: {m}"));
        let Some(class) = mapping.class_of_name(&shape.label) else {
            match mapping.unknown {
                UnknownCategories::Refuse => {
                    return Err(invalid(
                        "its label maps to no damage class (map it to crack, spalling or \
                         rebar, or skip unknown categories)"
                            .into(),
                    ));
                }
                UnknownCategories::Skip => {
                    *skipped.entry(shape.label.clone()).or_insert(0) += 1;
                    continue;
                }
            }
        };
        let mask = shape_mask(shape, size).map_err(invalid)?;
        image.add(class, &mask);
    }
    Ok(image)
}

fn shape_mask(shape: &LabelMeShape, (width, height): (u32, u32)) -> Result<Mask, String> {
    let kind = shape.shape_type.as_deref().unwrap_or("polygon");
    if let Some([x, y]) = vertex_outside(&shape.points, width, height) {
        return Err(format!(
            "vertex ({x}, {y}) is outside the {width}×{height} image"
        ));
    }
    let mut mask = Mask::empty(width, height);
    match (kind, shape.points.as_slice()) {
        ("polygon", points) if points.len() >= 3 => fill_polygon(&mut mask, points),
        ("rectangle", &[[x0, y0], [x1, y1]]) => {
            fill_polygon(&mut mask, &[[x0, y0], [x1, y0], [x1, y1], [x0, y1]]);
        }
        ("circle", &[[cx, cy], [px, py]]) => {
            let r2 = (px - cx).powi(2) + (py - cy).powi(2);
            for y in 0..height {
                for x in 0..width {
                    let (dx, dy) = (f64::from(x) + 0.5 - cx, f64::from(y) + 0.5 - cy);
                    if dx * dx + dy * dy <= r2 {
                        mask.data[(y * width + x) as usize] = 1;
                    }
                }
            }
        }
        ("polygon" | "rectangle" | "circle", points) => {
            return Err(format!(
                "a {kind} with {} points (a polygon needs 3 or more, a rectangle and a circle 2)",
                points.len()
            ));
        }
        (other, _) => {
            return Err(format!(
                "a {other} has no area: only polygon, rectangle and circle shapes give masks"
            ));
        }
    }
    Ok(mask)
}
