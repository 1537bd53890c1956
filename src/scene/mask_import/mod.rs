//! Damage masks from the formats segmenters and annotation tools write, into the dataset's
//! convention (`masks/<class>/<stem>.png`), and the twin's masks back out as COCO JSON.
//!
//! - `coco`: COCO instance JSON (Detectron2, MMDetection, CVAT): polygons, uncompressed and
//!   compressed RLE; read and written.
//! - `labelme`: LabelMe JSON (polygons, rectangles, circles).
//! - `png_classes`: class-index PNGs (a value per class, MMSegmentation) and colour or palette
//!   PNGs (a colour per class).
//! - `polygon`, `rle`: the rasterisation and run-length conventions they share.
//! - `destination`: which dataset image an annotation names, and the writing of its masks.
//!
//! The mapping from a file's categories, values or colours to damage classes is `ClassMapping`.
//! Every refusal is one line naming the annotation file (and the annotation, shape or image).

pub mod coco;
pub mod destination;
pub mod labelme;
pub mod png_classes;
pub mod polygon;
pub mod rle;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::scene::{DamageClass, Mask, SceneError};

/// What to do with an annotation whose category (label) maps to no damage class.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UnknownCategories {
    /// Refuse the file, naming the category: a silently dropped category would train its damage
    /// as background.
    #[default]
    Refuse,
    /// Skip such annotations and count them per category (CVAT projects often carry labels
    /// such as "vegetation" that are no damage).
    Skip,
}

/// How category names (COCO, LabelMe), pixel values (class-index PNGs) and colours (colour and
/// palette PNGs) map to damage classes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClassMapping {
    /// Category name, compared without case → class.
    pub names: BTreeMap<String, DamageClass>,
    /// Pixel value of a class-index PNG → class; other values are background.
    pub values: BTreeMap<u16, DamageClass>,
    /// Colour of a colour or palette PNG → class; other colours are background.
    pub colours: BTreeMap<[u8; 3], DamageClass>,
    pub unknown: UnknownCategories,
}

impl Default for ClassMapping {
    /// Each class's own identifier as its category name (`crack`, `spalling`, `rebar`), values
    /// 1, 2, 3 in channel order (0 is background, as MMSegmentation writes it), and the dataset's
    /// class colours (`DamageClass::default_colour`).
    fn default() -> ClassMapping {
        ClassMapping {
            names: DamageClass::ALL
                .into_iter()
                .map(|c| (c.id().to_string(), c))
                .collect(),
            values: DamageClass::ALL
                .into_iter()
                .map(|c| (c.channel() as u16 + 1, c))
                .collect(),
            colours: DamageClass::ALL
                .into_iter()
                .map(|c| (c.default_colour(), c))
                .collect(),
            unknown: UnknownCategories::Refuse,
        }
    }
}

impl ClassMapping {
    /// The class category `name` maps to (without case).
    pub fn class_of_name(&self, name: &str) -> Option<DamageClass> {
        let lower = name.to_lowercase();
        self.names
            .iter()
            .find(|(n, _)| n.to_lowercase() == lower)
            .map(|(_, &c)| c)
    }

    /// The classes `classes` name, once each, in channel order.
    pub fn distinct<'a>(classes: impl Iterator<Item = &'a DamageClass>) -> Vec<DamageClass> {
        let mut out: Vec<DamageClass> = classes.copied().collect();
        out.sort();
        out.dedup();
        out
    }
}

/// Parses one `KEY=CLASS` pair of the CLI or a settings file; the error says what is wrong.
pub fn parse_pair(text: &str) -> Result<(&str, DamageClass), String> {
    let (key, class) = text
        .rsplit_once('=')
        .ok_or_else(|| format!("{text:?} is not KEY=CLASS"))?;
    let class = DamageClass::from_id(class.trim()).ok_or_else(|| {
        format!(
            "{text:?}: {:?} is no damage class (crack, spalling or rebar)",
            class.trim()
        )
    })?;
    Ok((key.trim(), class))
}

/// Parses `RRGGBB` or `#RRGGBB`.
pub fn parse_colour(text: &str) -> Result<[u8; 3], String> {
    let hex = text.trim().trim_start_matches('#');
    let byte = |i: usize| {
        hex.get(i..i + 2)
            .and_then(|h| u8::from_str_radix(h, 16).ok())
    };
    match (hex.len(), byte(0), byte(2), byte(4)) {
        (6, Some(r), Some(g), Some(b)) => Ok([r, g, b]),
        _ => Err(format!("{text:?} is not a colour RRGGBB")),
    }
}

/// One annotated image of an annotation file: its name as the file gives it, its size, and its
/// mask per class the file speaks of (a COCO file's mapped categories, a LabelMe file's mapped
/// labels, every class of a PNG's table), empty when the image has none of it: an annotated image
/// without a crack says "no crack", and its mask file is written empty.
#[derive(Clone, Debug, PartialEq)]
pub struct AnnotatedImage {
    /// The file its annotations came from (the COCO or LabelMe file, the PNG), for messages.
    pub origin: PathBuf,
    pub file_name: String,
    pub size: (u32, u32),
    pub masks: BTreeMap<DamageClass, Mask>,
}

/// What one annotation file (or PNG folder) held.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Annotations {
    /// The file (or folder) read, for messages.
    pub source: PathBuf,
    pub images: Vec<AnnotatedImage>,
    /// Annotations skipped per unmapped category (`UnknownCategories::Skip` only).
    pub skipped: BTreeMap<String, usize>,
}

impl AnnotatedImage {
    /// An image of `size` with an empty mask for every class of `classes`.
    pub(crate) fn empty(
        origin: &Path,
        file_name: String,
        size: (u32, u32),
        classes: &[DamageClass],
    ) -> Self {
        AnnotatedImage {
            origin: origin.to_path_buf(),
            file_name,
            size,
            masks: classes
                .iter()
                .map(|&c| (c, Mask::empty(size.0, size.1)))
                .collect(),
        }
    }

    /// ORs `mask` (of this image's size) into the class's mask.
    pub(crate) fn add(&mut self, class: DamageClass, mask: &Mask) {
        let target = self
            .masks
            .entry(class)
            .or_insert_with(|| Mask::empty(mask.width, mask.height));
        for (a, &b) in target.data.iter_mut().zip(&mask.data) {
            *a |= u8::from(b != 0);
        }
    }
}

/// Checks an annotated image's size against the limits before a mask is allocated for it.
pub(crate) fn check_size(
    file: &Path,
    image: &str,
    w: i64,
    h: i64,
) -> Result<(u32, u32), SceneError> {
    if w < 0 || h < 0 {
        return Err(SceneError::invalid(
            file,
            format!("image {image:?} has size {w}×{h}"),
        ));
    }
    crate::scene::limits::check_image_size(w as u64, h as u64)
        .map_err(|m| SceneError::invalid(file, format!("image {image:?}: {m}")))?;
    Ok((w as u32, h as u32))
}

/// Reads an annotation file as JSON of type `T`: a regular file of at most
/// `limits::MAX_ANNOTATION_BYTES`; malformed JSON is one line naming the file, the line and
/// the column.
pub(crate) fn read_json<T: serde::de::DeserializeOwned>(
    path: &Path,
    format: &str,
) -> Result<T, SceneError> {
    let bytes =
        crate::scene::files::read_regular(path, crate::scene::limits::MAX_ANNOTATION_BYTES)?;
    serde_json::from_slice(&bytes)
        .map_err(|e| SceneError::invalid(path, format!("not {format} JSON: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_and_colours_parse_and_say_what_is_wrong() {
        assert_eq!(
            parse_pair("Crack-Large=crack"),
            Ok(("Crack-Large", DamageClass::Crack))
        );
        assert_eq!(parse_pair(" 2 = rebar "), Ok(("2", DamageClass::Rebar)));
        assert!(parse_pair("crack").unwrap_err().contains("KEY=CLASS"));
        assert!(
            parse_pair("a=spall")
                .unwrap_err()
                .contains("no damage class")
        );
        assert_eq!(parse_colour("#ff00C0"), Ok([255, 0, 192]));
        assert!(parse_colour("ff00").is_err());
        let mapping = ClassMapping::default();
        assert_eq!(mapping.class_of_name("CRACK"), Some(DamageClass::Crack));
        assert_eq!(
            ClassMapping::distinct(mapping.values.values()),
            DamageClass::ALL.to_vec()
        );
    }
}
