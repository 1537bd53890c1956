//! Where imported masks go: each annotated image is matched to a dataset view by name, checked
//! against the view's image size, and written as `masks/<class>/<view name>.png` (the folder
//! convention `MaskFolder` reads). Everything is matched and checked before the first file is
//! written, so a refused import leaves the dataset as it was; each file is written atomically.
//!
//! Matching: the annotation's image name with `\` as `/`, without its extension, must equal the
//! view's name (its image path under `images/` without extension, `a/01` for `images/a/01.jpg`)
//! or end in `/` + that name (`../images/a/01.jpg`, `C:\survey\images\01.jpg`). When several views
//! match, the longest name wins; two of the same length are ambiguous and refused.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Serialize;

use crate::scene::files::image_size;
use crate::scene::load::save_mask_png;
use crate::scene::mask_import::{AnnotatedImage, Annotations};
use crate::scene::open::summarise;
use crate::scene::{DamageClass, Dataset, SceneError};

/// What arrived for one class.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ClassArrival {
    /// Mask files written (empty ones included: an annotated image without the class).
    pub files: usize,
    /// Of them, masks with at least one damage pixel.
    pub with_damage: usize,
    pub pixels: u64,
}

/// What an import wrote.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ImportSummary {
    /// Annotated images written to their views.
    pub images: usize,
    pub classes: BTreeMap<DamageClass, ClassArrival>,
    /// Annotated images that name no view of the dataset (not written).
    pub unmatched: Vec<String>,
    /// Annotations (pixels, for PNGs) skipped per unmapped category, value or colour.
    pub skipped: BTreeMap<String, usize>,
}

impl ImportSummary {
    /// The warnings to print: images not written and categories skipped.
    pub fn warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !self.unmatched.is_empty() {
            out.push(summarise(
                "annotated images name no view of the dataset and were not written",
                &self.unmatched,
            ));
        }
        for (what, n) in &self.skipped {
            out.push(format!(
                "skipped {n} of {what:?}: it maps to no damage class"
            ));
        }
        out
    }
}

/// The name an annotation gives its image, as a view name would be written: `/`-separated,
/// without extension or a leading `./`.
fn comparable(file_name: &str) -> String {
    let slashed = file_name.replace('\\', "/");
    let path = Path::new(&slashed);
    let stem = match (path.parent(), path.file_stem()) {
        (Some(parent), Some(stem)) if !parent.as_os_str().is_empty() => {
            format!("{}/{}", parent.to_string_lossy(), stem.to_string_lossy())
        }
        (_, Some(stem)) => stem.to_string_lossy().into_owned(),
        _ => slashed.clone(),
    };
    stem.trim_start_matches("./").to_string()
}

/// The index of the view `file_name` names (see the module comment); an error message when two
/// views match equally well.
fn view_for(dataset: &Dataset, file_name: &str) -> Result<Option<usize>, String> {
    let wanted = comparable(file_name);
    let mut best: Option<(usize, usize)> = None;
    let mut tie = None;
    for (index, view) in dataset.views.iter().enumerate() {
        let name = view.name.as_str();
        let matches = wanted == name
            || (wanted.len() > name.len()
                && wanted.ends_with(name)
                && wanted.as_bytes()[wanted.len() - name.len() - 1] == b'/');
        if !matches {
            continue;
        }
        match best {
            Some((_, len)) if len > name.len() => {}
            Some((other, len)) if len == name.len() => tie = Some((other, index)),
            _ => {
                best = Some((index, name.len()));
                tie = None;
            }
        }
    }
    if let Some((a, b)) = tie {
        return Err(format!(
            "image {file_name:?} matches views {:?} and {:?} equally: name it by its path under \
             images/",
            dataset.views[a].name, dataset.views[b].name
        ));
    }
    Ok(best.map(|(index, _)| index))
}

/// Matches every annotated image to its view and checks its size against the view's image, then
/// writes the masks under `masks_dir` (normally the dataset's `masks/`).
pub fn write_annotations(
    dataset: &Dataset,
    annotations: &Annotations,
    masks_dir: &Path,
) -> Result<ImportSummary, SceneError> {
    let mut summary = ImportSummary {
        skipped: annotations.skipped.clone(),
        ..ImportSummary::default()
    };
    let mut planned: Vec<(usize, &AnnotatedImage)> = Vec::new();
    let mut taken: BTreeMap<usize, &AnnotatedImage> = BTreeMap::new();
    for image in &annotations.images {
        let index = view_for(dataset, &image.file_name)
            .map_err(|m| SceneError::invalid(&image.origin, m))?;
        let Some(index) = index else {
            summary.unmatched.push(image.file_name.clone());
            continue;
        };
        let view = &dataset.views[index];
        if let Some(earlier) = taken.insert(index, image) {
            return Err(SceneError::invalid(
                &image.origin,
                format!(
                    "images {:?} and {:?} both name view {:?}",
                    earlier.file_name, image.file_name, view.name
                ),
            ));
        }
        let stored = image_size(&view.image_path)?;
        if stored != image.size {
            return Err(SceneError::invalid(
                &image.origin,
                format!(
                    "image {:?} is {}×{} here but {} is {}×{}",
                    image.file_name,
                    image.size.0,
                    image.size.1,
                    view.image_path.display(),
                    stored.0,
                    stored.1
                ),
            ));
        }
        planned.push((index, image));
    }
    if planned.is_empty() && !annotations.images.is_empty() {
        return Err(SceneError::invalid(
            &annotations.source,
            format!(
                "none of its {} images is a view of {} (views are named like {})",
                annotations.images.len(),
                dataset.root.display(),
                dataset.example_view_names()
            ),
        ));
    }
    for (index, image) in planned {
        let name = &dataset.views[index].name;
        for (&class, mask) in &image.masks {
            let path = masks_dir.join(class.id()).join(format!("{name}.png"));
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).map_err(|e| SceneError::io(parent, e))?;
            }
            save_mask_png(&path, mask)?;
            let arrival = summary.classes.entry(class).or_default();
            let pixels = mask.count();
            arrival.files += 1;
            arrival.with_damage += usize::from(pixels > 0);
            arrival.pixels += pixels as u64;
        }
        summary.images += 1;
    }
    Ok(summary)
}
