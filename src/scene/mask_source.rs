//! Where a view's masks come from: the seam between the loaders (`Dataset::load_view` and
//! `load_view_masks`, which undistort and resize) and whatever stores the masks. A source hands
//! out masks at the view's stored image size and checks that size; it knows nothing of scales or
//! cameras. The folder convention (`masks/<class>/<stem>.png`, colour-coded `masks/<stem>.png`,
//! COLMAP's ignore masks `masks/<image file>.png`, a synthetic survey's `truth/masks/`) is
//! `MaskFolder`; masks already in memory are `InMemoryMasks`. Another format (COCO polygons, a
//! segmenter's output) is one more implementation of `MaskSource`, and the call sites stay.

use std::collections::BTreeMap;
use std::fmt::Debug;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::scene::masks::{ignore_mask_path, read_ignore_mask, read_view_masks};
use crate::scene::{DamageClass, Mask, SceneError, View};

/// A store of damage masks and ignore masks, read per view.
pub trait MaskSource: Debug + Send + Sync {
    /// View `view`'s damage masks at its stored image size `stored` (width, height); classes
    /// without a mask are absent. A mask of another size is an error naming the mask and the
    /// image.
    fn damage_masks(
        &self,
        view: &View,
        stored: (u32, u32),
    ) -> Result<BTreeMap<DamageClass, Mask>, SceneError>;

    /// Whether the source holds an ignore mask for `view` (1 = use the pixel, 0 = ignore it).
    /// The dataset's own per-view ignore mask (`View::ignore_mask`) wins over it.
    fn has_ignore_mask(&self, view: &View) -> bool;

    /// View `view`'s ignore mask at its stored image size (None when the source has none); a
    /// mask of another size is an error naming it.
    fn ignore_mask(&self, view: &View, stored: (u32, u32)) -> Result<Option<Mask>, SceneError>;

    /// Whether the source can be read at all (a folder that still exists).
    fn is_available(&self) -> bool {
        true
    }

    /// Where the masks come from, in words, for reports (a folder's path).
    fn describe(&self) -> String;
}

/// Masks in a folder by the dataset convention: per-class binary `<dir>/<class>/<stem>.png`,
/// colour-coded `<dir>/<stem>.png` OR-ed into them, ignore masks `<dir>/<image file>.png`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MaskFolder {
    dir: PathBuf,
}

impl MaskFolder {
    pub fn new(dir: impl Into<PathBuf>) -> MaskFolder {
        MaskFolder { dir: dir.into() }
    }

    /// A synthetic survey's clean masks, `<root>/truth/masks/` (written by `damage-twin synth`;
    /// the survey's own `masks/` may be deliberately corrupted).
    pub fn truth(root: &Path) -> MaskFolder {
        MaskFolder::new(root.join("truth").join("masks"))
    }

    /// The folder as a shared source for `Dataset::masks`.
    pub fn shared(dir: impl Into<PathBuf>) -> Arc<dyn MaskSource> {
        Arc::new(MaskFolder::new(dir))
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

impl MaskSource for MaskFolder {
    fn damage_masks(
        &self,
        view: &View,
        stored: (u32, u32),
    ) -> Result<BTreeMap<DamageClass, Mask>, SceneError> {
        read_view_masks(
            &self.dir,
            &view.name,
            &view.image_path,
            stored,
            view.ignore_mask.as_deref(),
        )
    }

    fn has_ignore_mask(&self, view: &View) -> bool {
        ignore_mask_path(&self.dir, &view.name, &view.image_path).is_some()
    }

    fn ignore_mask(&self, view: &View, stored: (u32, u32)) -> Result<Option<Mask>, SceneError> {
        match ignore_mask_path(&self.dir, &view.name, &view.image_path) {
            Some(path) => read_ignore_mask(&path, &view.image_path, stored).map(Some),
            None => Ok(None),
        }
    }

    fn is_available(&self) -> bool {
        self.dir.is_dir()
    }

    fn describe(&self) -> String {
        self.dir.display().to_string()
    }
}

/// One view's masks held in memory, at the stored image size.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewMasks {
    pub damage: BTreeMap<DamageClass, Mask>,
    pub ignore: Option<Mask>,
}

/// Masks made in memory (corrupted copies in a study, a segmenter's output) by view name; a view
/// not named has none. Values are read as a mask file is: any non-zero value is 1.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InMemoryMasks {
    views: BTreeMap<String, ViewMasks>,
}

impl InMemoryMasks {
    /// Sets view `name`'s damage mask of `class`.
    pub fn insert_damage(&mut self, name: &str, class: DamageClass, mask: Mask) {
        let entry = self.views.entry(name.to_string()).or_default();
        entry.damage.insert(class, binary(mask));
    }

    /// Sets view `name`'s ignore mask.
    pub fn insert_ignore(&mut self, name: &str, mask: Mask) {
        self.views.entry(name.to_string()).or_default().ignore = Some(binary(mask));
    }
}

/// 0/1 values, as `masks::read_binary_mask` reads a 0/255 file.
fn binary(mut mask: Mask) -> Mask {
    for v in &mut mask.data {
        *v = u8::from(*v != 0);
    }
    mask
}

/// Refuses a mask whose size is not the image's, naming the image (there is no mask file).
fn checked(view: &View, what: &str, mask: &Mask, stored: (u32, u32)) -> Result<Mask, SceneError> {
    if (mask.width, mask.height) != stored {
        return Err(SceneError::invalid(
            &view.image_path,
            format!(
                "its {what} mask is {}×{} but the image is {}×{}",
                mask.width, mask.height, stored.0, stored.1
            ),
        ));
    }
    Ok(mask.clone())
}

impl MaskSource for InMemoryMasks {
    fn damage_masks(
        &self,
        view: &View,
        stored: (u32, u32),
    ) -> Result<BTreeMap<DamageClass, Mask>, SceneError> {
        let Some(masks) = self.views.get(&view.name) else {
            return Ok(BTreeMap::new());
        };
        masks
            .damage
            .iter()
            .map(|(&class, mask)| Ok((class, checked(view, class.id(), mask, stored)?)))
            .collect()
    }

    fn has_ignore_mask(&self, view: &View) -> bool {
        self.views
            .get(&view.name)
            .is_some_and(|m| m.ignore.is_some())
    }

    fn ignore_mask(&self, view: &View, stored: (u32, u32)) -> Result<Option<Mask>, SceneError> {
        match self.views.get(&view.name).and_then(|m| m.ignore.as_ref()) {
            Some(mask) => checked(view, "ignore", mask, stored).map(Some),
            None => Ok(None),
        }
    }

    fn describe(&self) -> String {
        format!("masks in memory ({} views)", self.views.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Camera, Intrinsics, Split};

    fn view(name: &str, image_path: &Path) -> View {
        View {
            name: name.to_string(),
            image_path: image_path.to_path_buf(),
            camera: Camera::look_at(
                Intrinsics {
                    width: 4,
                    height: 3,
                    fx: 4.0,
                    fy: 4.0,
                    cx: 2.0,
                    cy: 1.5,
                },
                glam::Vec3::Z,
                glam::Vec3::ZERO,
                glam::Vec3::Y,
            ),
            distortion: None,
            split: Split::Unspecified,
            ignore_mask: None,
        }
    }

    #[test]
    fn masks_in_memory_read_as_the_same_masks_written_as_files() {
        let dir = tempfile::tempdir().unwrap();
        let image = dir.path().join("images/v.jpg");
        let mut crack = Mask::empty(4, 3);
        crack.data[5] = 1;
        crack.data[7] = 255;
        std::fs::create_dir_all(dir.path().join("masks/crack")).unwrap();
        let grey = crack.data.iter().map(|&v| if v != 0 { 255 } else { 0 });
        image::GrayImage::from_raw(4, 3, grey.collect())
            .unwrap()
            .save(dir.path().join("masks/crack/v.png"))
            .unwrap();
        std::fs::write(dir.path().join("masks/v.jpg.png"), b"").unwrap();
        let folder = MaskFolder::new(dir.path().join("masks"));
        let mut memory = InMemoryMasks::default();
        memory.insert_damage("v", DamageClass::Crack, crack);

        let v = view("v", &image);
        let from_file = folder.damage_masks(&v, (4, 3)).unwrap();
        assert_eq!(memory.damage_masks(&v, (4, 3)).unwrap(), from_file);
        assert_eq!(from_file[&DamageClass::Crack].count(), 2);
        assert!(folder.has_ignore_mask(&v) && !memory.has_ignore_mask(&v));
        let other = view("w", &image);
        assert!(memory.damage_masks(&other, (4, 3)).unwrap().is_empty());
        assert!(folder.is_available() && folder.describe().ends_with("masks"));
    }

    #[test]
    fn an_in_memory_mask_of_another_size_names_the_image() {
        let mut memory = InMemoryMasks::default();
        memory.insert_damage("v", DamageClass::Rebar, Mask::empty(2, 2));
        memory.insert_ignore("v", Mask::empty(4, 3));
        let v = view("v", Path::new("/data/images/v.jpg"));
        let err = memory.damage_masks(&v, (4, 3)).unwrap_err().to_string();
        assert!(
            err.contains("/data/images/v.jpg") && err.contains("rebar mask is 2×2"),
            "{err}"
        );
        assert!(memory.ignore_mask(&v, (4, 3)).unwrap().is_some());
    }
}
