//! COCO instance-segmentation JSON (Detectron2, MMDetection, CVAT's "COCO 1.0"): `images`
//! (`id`, `file_name`, `width`, `height`), `categories` (`id`, `name`) and `annotations`
//! (`image_id`, `category_id`, `segmentation`: a list of polygons `[x0, y0, x1, y1, …]` in
//! pixels, or an RLE `{"size": [height, width], "counts": …}` with the counts as a list or as
//! COCO's compact string). Read into per-class masks, and written from them (one RLE annotation
//! per image and class, uncompressed counts and `iscrowd: 1`, as CVAT writes masks).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::scene::mask_import::polygon::{fill_polygon, vertex_outside};
use crate::scene::mask_import::rle::{counts_from_string, counts_of_mask, mask_from_counts};
use crate::scene::mask_import::{
    AnnotatedImage, Annotations, ClassMapping, UnknownCategories, check_size, read_json,
};
use crate::scene::{DamageClass, Mask, SceneError};

#[derive(Deserialize)]
struct CocoFile {
    images: Vec<CocoImage>,
    #[serde(default)]
    annotations: Vec<CocoAnnotation>,
    categories: Vec<CocoCategory>,
}

#[derive(Deserialize, Serialize)]
struct CocoImage {
    id: i64,
    file_name: String,
    width: i64,
    height: i64,
}

#[derive(Deserialize)]
struct CocoAnnotation {
    #[serde(default)]
    id: Option<i64>,
    image_id: i64,
    category_id: i64,
    #[serde(default)]
    segmentation: Option<Value>,
}

#[derive(Deserialize, Serialize)]
struct CocoCategory {
    id: i64,
    name: String,
}

/// Reads the COCO file at `path` into masks per image and mapped class. Refused, naming the
/// file: malformed JSON, an annotation naming an image or category the file does not list, a
/// category without a class (unless `mapping.unknown` skips it), an annotation without a
/// segmentation, a polygon vertex outside its image, an RLE whose size or run total is not its
/// image's.
pub fn read_coco(path: &Path, mapping: &ClassMapping) -> Result<Annotations, SceneError> {
    let file: CocoFile = read_json(path, "COCO")?;
    let invalid = |m: String| SceneError::invalid(path, m);
    let mut categories: HashMap<i64, (&str, Option<DamageClass>)> = HashMap::new();
    for c in &file.categories {
        categories.insert(c.id, (&c.name, mapping.class_of_name(&c.name)));
    }
    let classes =
        ClassMapping::distinct(categories.values().filter_map(|(_, class)| class.as_ref()));
    let mut images: Vec<AnnotatedImage> = Vec::with_capacity(file.images.len());
    let mut index_of: HashMap<i64, usize> = HashMap::new();
    for image in &file.images {
        let size = check_size(path, &image.file_name, image.width, image.height)?;
        if index_of.insert(image.id, images.len()).is_some() {
            return Err(invalid(format!("image id {} is listed twice", image.id)));
        }
        images.push(AnnotatedImage::empty(
            path,
            image.file_name.clone(),
            size,
            &classes,
        ));
    }
    let mut skipped: BTreeMap<String, usize> = BTreeMap::new();
    for (k, a) in file.annotations.iter().enumerate() {
        let what = match a.id {
            Some(id) => format!("annotation {id}"),
            None => format!("annotation #{}", k + 1),
        };
        let Some(&(name, class)) = categories.get(&a.category_id) else {
            return Err(invalid(format!(
                "{what}: category_id {} is not among the file's categories",
                a.category_id
            )));
        };
        let Some(&at) = index_of.get(&a.image_id) else {
            return Err(invalid(format!(
                "{what}: image_id {} is not among the file's images",
                a.image_id
            )));
        };
        let Some(class) = class else {
            match mapping.unknown {
                UnknownCategories::Refuse => {
                    return Err(invalid(format!(
                        "{what}: category {name:?} (id {}) maps to no damage class (map it to \
                         crack, spalling or rebar, or skip unknown categories)",
                        a.category_id
                    )));
                }
                UnknownCategories::Skip => {
                    *skipped.entry(name.to_string()).or_insert(0) += 1;
                    continue;
                }
            }
        };
        let image = &mut images[at];
        let what = format!("{what} (image {:?})", image.file_name);
        let mask = segmentation_mask(a.segmentation.as_ref(), image.size)
            .map_err(|m| invalid(format!("{what}: {m}")))?;
        image.add(class, &mask);
    }
    Ok(Annotations {
        source: path.to_path_buf(),
        images,
        skipped,
    })
}

/// The mask of one annotation's `segmentation` on an image of `size`.
fn segmentation_mask(segmentation: Option<&Value>, size: (u32, u32)) -> Result<Mask, String> {
    let (width, height) = size;
    match segmentation {
        None | Some(Value::Null) => Err("has no segmentation (a box alone gives no mask)".into()),
        Some(Value::Array(polygons)) => {
            let mut mask = Mask::empty(width, height);
            for (p, polygon) in polygons.iter().enumerate() {
                let points =
                    polygon_points(polygon).map_err(|m| format!("polygon {}: {m}", p + 1))?;
                if let Some([x, y]) = vertex_outside(&points, width, height) {
                    return Err(format!(
                        "polygon {} has vertex ({x}, {y}) outside the {width}×{height} image",
                        p + 1
                    ));
                }
                fill_polygon(&mut mask, &points);
            }
            Ok(mask)
        }
        Some(Value::Object(rle)) => {
            let rle_size: Option<Vec<u64>> = rle
                .get("size")
                .and_then(Value::as_array)
                .map(|s| s.iter().filter_map(Value::as_u64).collect());
            match rle_size.as_deref() {
                Some(&[h, w]) if (w, h) == (u64::from(width), u64::from(height)) => {}
                Some(&[h, w]) => {
                    return Err(format!(
                        "RLE size is {w}×{h} (width×height) but the image is {width}×{height}"
                    ));
                }
                _ => return Err("RLE has no \"size\": [height, width]".into()),
            }
            let counts = match rle.get("counts") {
                Some(Value::String(text)) => counts_from_string(text)?,
                Some(Value::Array(list)) => list
                    .iter()
                    .map(|v| {
                        v.as_u64()
                            .ok_or("RLE counts hold a value that is not a count")
                    })
                    .collect::<Result<Vec<u64>, _>>()?,
                _ => return Err("RLE has no \"counts\" (a list or a string)".into()),
            };
            mask_from_counts(&counts, width, height)
        }
        Some(other) => Err(format!(
            "segmentation is {}, neither polygons nor an RLE",
            kind_of(other)
        )),
    }
}

/// A polygon's flat `[x0, y0, x1, y1, …]` as points.
fn polygon_points(polygon: &Value) -> Result<Vec<[f64; 2]>, String> {
    let Some(flat) = polygon.as_array() else {
        return Err(format!(
            "is {}, not a list of coordinates",
            kind_of(polygon)
        ));
    };
    if flat.len() % 2 != 0 || flat.len() < 6 {
        return Err(format!(
            "has {} coordinates: a polygon needs x, y pairs for at least three vertices",
            flat.len()
        ));
    }
    let coords: Vec<f64> = flat
        .iter()
        .map(|v| v.as_f64().ok_or("holds a coordinate that is not a number"))
        .collect::<Result<_, _>>()?;
    Ok(coords.chunks_exact(2).map(|c| [c[0], c[1]]).collect())
}

fn kind_of(value: &Value) -> &'static str {
    match value {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "an object",
    }
}

/// One image to write: its file name as the annotation tool knows it and its masks per class.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportImage {
    pub file_name: String,
    pub width: u32,
    pub height: u32,
    pub masks: BTreeMap<DamageClass, Mask>,
}

#[derive(Serialize)]
struct ExportFile {
    info: ExportInfo,
    images: Vec<CocoImage>,
    categories: Vec<CocoCategory>,
    annotations: Vec<ExportAnnotation>,
}

#[derive(Serialize)]
struct ExportInfo {
    description: &'static str,
}

#[derive(Serialize)]
struct ExportAnnotation {
    id: i64,
    image_id: i64,
    category_id: i64,
    segmentation: ExportRle,
    area: u64,
    bbox: [u32; 4],
    iscrowd: u8,
}

#[derive(Serialize)]
struct ExportRle {
    size: [u32; 2],
    counts: Vec<u64>,
}

/// The category id a class is written with: its channel + 1 (COCO ids start at 1).
pub fn category_id(class: DamageClass) -> i64 {
    class.channel() as i64 + 1
}

/// Writes `images` as a COCO file at `path`, atomically: every damage class as a category, one
/// RLE annotation per image and non-empty class (an image without damage is listed with none).
pub fn write_coco(path: &Path, images: &[ExportImage]) -> Result<(), SceneError> {
    let mut annotations = Vec::new();
    for (i, image) in images.iter().enumerate() {
        for (&class, mask) in &image.masks {
            let area = mask.count() as u64;
            if area == 0 {
                continue;
            }
            annotations.push(ExportAnnotation {
                id: annotations.len() as i64 + 1,
                image_id: i as i64 + 1,
                category_id: category_id(class),
                segmentation: ExportRle {
                    size: [mask.height, mask.width],
                    counts: counts_of_mask(mask),
                },
                area,
                bbox: bounding_box(mask),
                iscrowd: 1,
            });
        }
    }
    let file = ExportFile {
        info: ExportInfo {
            description: "damage masks rendered by damage-twin",
        },
        images: images
            .iter()
            .enumerate()
            .map(|(i, image)| CocoImage {
                id: i as i64 + 1,
                file_name: image.file_name.clone(),
                width: i64::from(image.width),
                height: i64::from(image.height),
            })
            .collect(),
        categories: DamageClass::ALL
            .into_iter()
            .map(|c| CocoCategory {
                id: category_id(c),
                name: c.id().to_string(),
            })
            .collect(),
        annotations,
    };
    crate::scene::atomic::write_atomic(path, |w| {
        serde_json::to_writer(&mut *w, &file).map_err(std::io::Error::other)
    })
}

/// COCO's `[x, y, width, height]` of the set pixels (`[0, 0, 0, 0]` for none).
fn bounding_box(mask: &Mask) -> [u32; 4] {
    let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
    for y in 0..mask.height {
        for x in 0..mask.width {
            if mask.get(x, y) {
                (x0, y0) = (x0.min(x), y0.min(y));
                (x1, y1) = (x1.max(x + 1), y1.max(y + 1));
            }
        }
    }
    if x0 == u32::MAX {
        return [0; 4];
    }
    [x0, y0, x1 - x0, y1 - y0]
}
