//! Semantic-segmentation PNGs, one per image, named by the image's stem: class-index PNGs (grey,
//! 8 or 16 bit, one value per class, 0 background: MMSegmentation's and most segmentation code's
//! output) and colour PNGs (RGB, or a palette PNG, which decodes to its palette's colours: one
//! colour per class, black background: Pascal VOC's `SegmentationClass`). Values and colours are
//! matched exactly (a palette holds exact colours; a lossy-compressed mask is not a class map).

use std::collections::BTreeMap;
use std::path::Path;

use crate::scene::files::{EntryBudget, walk_files};
use crate::scene::limits::MAX_LISTED_ENTRIES;
use crate::scene::load::decode;
use crate::scene::mask_import::{AnnotatedImage, Annotations, ClassMapping, UnknownCategories};
use crate::scene::{DamageClass, SceneError};

fn is_png(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
}

/// Reads every PNG under `dir` (sub-folders too, as images may be in them) as a class map.
/// Each image gets a mask for every class of the table its PNG uses (values for grey PNGs,
/// colours for colour PNGs), empty when absent. A value or colour that maps to no class (other
/// than background: 0, black) is refused naming the PNG and the value, unless `mapping.unknown`
/// skips it (then its pixels are background and counted per value).
pub fn read_png_folder(dir: &Path, mapping: &ClassMapping) -> Result<Annotations, SceneError> {
    if !dir.is_dir() {
        return Err(SceneError::invalid(dir, "is not a folder of class PNGs"));
    }
    let mut budget = EntryBudget::new(MAX_LISTED_ENTRIES);
    let names = walk_files(dir, 8, &mut budget, is_png);
    if names.is_empty() {
        return Err(SceneError::invalid(dir, "holds no PNG file"));
    }
    let mut images = Vec::with_capacity(names.len());
    let mut skipped = BTreeMap::new();
    for name in names {
        let path = dir.join(&name);
        images.push(read_class_png(&path, name, mapping, &mut skipped)?);
    }
    Ok(Annotations {
        source: dir.to_path_buf(),
        images,
        skipped,
    })
}

/// One class PNG at `path`, known to the import as `name`.
pub fn read_class_png(
    path: &Path,
    name: String,
    mapping: &ClassMapping,
    skipped: &mut BTreeMap<String, usize>,
) -> Result<AnnotatedImage, SceneError> {
    let img = decode(path)?;
    let size = (img.width(), img.height());
    // Each pixel as a key of its table (`None`: background): a colour as 0x00RRGGBB, or a grey
    // value; the table keyed the same way.
    let keys: Vec<Option<u32>>;
    let table: BTreeMap<u32, DamageClass>;
    let describe: fn(u32) -> String;
    if img.color().has_color() {
        table = mapping
            .colours
            .iter()
            .map(|(&[r, g, b], &class)| (u32::from_be_bytes([0, r, g, b]), class))
            .collect();
        keys = img
            .to_rgb8()
            .pixels()
            .map(|p| {
                let [r, g, b] = p.0;
                (p.0 != [0, 0, 0]).then_some(u32::from_be_bytes([0, r, g, b]))
            })
            .collect();
        describe = |k| format!("colour {k:06x}");
    } else {
        table = mapping
            .values
            .iter()
            .map(|(&v, &class)| (u32::from(v), class))
            .collect();
        let sixteen = matches!(img.color(), image::ColorType::L16 | image::ColorType::La16);
        keys = img
            .to_luma16()
            .pixels()
            .map(|p| {
                // An 8-bit PNG widens to 16 bits as v · 257; its values are the 8-bit ones.
                let v = if sixteen { p.0[0] } else { p.0[0] / 257 };
                (v != 0).then_some(u32::from(v))
            })
            .collect();
        describe = |k| format!("value {k}");
    }
    let classes = ClassMapping::distinct(table.values());
    let mut image = AnnotatedImage::empty(path, name, size, &classes);
    let mut unmapped: BTreeMap<u32, usize> = BTreeMap::new();
    for (i, key) in keys.into_iter().enumerate() {
        let Some(key) = key else { continue };
        match table.get(&key).copied() {
            Some(class) => {
                if let Some(mask) = image.masks.get_mut(&class) {
                    mask.data[i] = 1;
                }
            }
            None => *unmapped.entry(key).or_insert(0) += 1,
        }
    }
    if let Some((&key, &pixels)) = unmapped.iter().next()
        && mapping.unknown == UnknownCategories::Refuse
    {
        return Err(SceneError::invalid(
            path,
            format!(
                "{} ({pixels} pixels) maps to no damage class{} (map it to crack, spalling or \
                 rebar, or skip unknown categories)",
                describe(key),
                match unmapped.len() {
                    1 => String::new(),
                    n => format!(", nor do {} other values or colours", n - 1),
                }
            ),
        ));
    }
    for (key, pixels) in unmapped {
        *skipped.entry(describe(key)).or_insert(0) += pixels;
    }
    Ok(image)
}
