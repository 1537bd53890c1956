//! Views decoded once: an opt-in cache of a dataset's loaded views (photo, damage masks, ignore
//! mask, per view and scale) for a job that reads the same views again and again. The survey
//! update's phases (near floaters, light fit, seeds, selection, crops, held-out scoring) each
//! loaded every view afresh: the decodes and resizes of the masks and photos were about a
//! tenth of the update's fixed phases. Off unless a job asks (`Dataset::keep_loaded_views`), so
//! other jobs keep their memory; dropped with the last clone of the dataset holding it.
//! It must not change what a load returns: a cached view is the fresh load, bit for bit.

use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex, PoisonError};

use crate::scene::{Camera, DamageClass, ImageScale, LoadedView, Mask};

/// A view's camera at a scale with its damage masks, as `Dataset::load_view_masks` gives them.
pub type ViewMasks = (Camera, BTreeMap<DamageClass, Mask>);

/// Loaded views by (view index, scale): whole ones (`Dataset::load_view`) and, at scales no
/// whole view was loaded at, the masks alone (`Dataset::load_view_masks` of the dataset's own
/// masks, which decodes no photo).
#[derive(Default)]
pub struct ViewCache {
    views: Mutex<HashMap<(usize, ImageScale), Arc<LoadedView>>>,
    masks: Mutex<HashMap<(usize, ImageScale), Arc<ViewMasks>>>,
}

impl std::fmt::Debug for ViewCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ViewCache")
            .field("views", &lock(&self.views).len())
            .field("masks", &lock(&self.masks).len())
            .finish()
    }
}

/// The map behind `mutex`. A panic while it was held cannot leave it half-written (every
/// insert is one call), so a poisoned lock is taken as it is.
fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

impl ViewCache {
    pub fn new() -> Self {
        Self::default()
    }

    /// View `index` at `scale` when it was loaded whole before.
    pub fn view(&self, index: usize, scale: ImageScale) -> Option<Arc<LoadedView>> {
        lock(&self.views).get(&(index, scale)).cloned()
    }

    /// Keeps `view` as view `index` at `scale`.
    pub fn keep_view(&self, index: usize, scale: ImageScale, view: Arc<LoadedView>) {
        lock(&self.views).insert((index, scale), view);
    }

    /// View `index`'s camera and damage masks at `scale`: from the whole view when one was
    /// loaded at that scale, else from the masks kept alone.
    pub fn masks(&self, index: usize, scale: ImageScale) -> Option<ViewMasks> {
        if let Some(view) = self.view(index, scale) {
            return Some((view.camera, view.masks.clone()));
        }
        lock(&self.masks)
            .get(&(index, scale))
            .map(|kept| kept.as_ref().clone())
    }

    /// Keeps view `index`'s camera and damage masks at `scale`.
    pub fn keep_masks(&self, index: usize, scale: ImageScale, masks: ViewMasks) {
        lock(&self.masks).insert((index, scale), Arc::new(masks));
    }

    /// Whole views and mask sets kept.
    pub fn len(&self) -> usize {
        lock(&self.views).len() + lock(&self.masks).len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use crate::scene::open::OpenOptions;
    use crate::scene::{Dataset, LoadedView, MaskFolder, MaskSource};

    use super::*;

    /// A small synthetic survey (four views of the demo building at 96×54, with damage masks
    /// and truth masks), and the tempdir holding it.
    fn survey() -> (tempfile::TempDir, Dataset) {
        let dir = tempfile::tempdir().expect("temp dir");
        let params = crate::synth::params::SynthParams {
            width: 96,
            height: 54,
            views: 4,
            surveys: 1,
            sparse_points: 500,
            ..crate::synth::params::SynthParams::demo(dir.path())
        };
        crate::synth::generate::generate(&params, &|_, _| {}).expect("synth");
        let root: PathBuf = dir.path().join("survey-1");
        let dataset = Dataset::open(&root, &OpenOptions::default()).expect("opens");
        (dir, dataset)
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    fn assert_same_view(got: &LoadedView, want: &LoadedView, what: &str) {
        assert_eq!(got.name, want.name, "{what}");
        assert_eq!(got.camera, want.camera, "{what}: camera");
        assert_eq!(
            (got.image.width, got.image.height),
            (want.image.width, want.image.height),
            "{what}: size"
        );
        assert!(
            bits(&got.image.data) == bits(&want.image.data),
            "{what}: photo"
        );
        assert_eq!(got.masks, want.masks, "{what}: masks");
        assert_eq!(got.ignore, want.ignore, "{what}: ignore mask");
    }

    #[test]
    fn a_kept_view_is_the_fresh_load_bit_for_bit() {
        let (_dir, fresh) = survey();
        assert!(fresh.view_cache.is_none(), "off unless asked");
        let mut kept = fresh.clone();
        kept.keep_loaded_views();
        let own = fresh.masks.clone().expect("the survey has masks");
        let truth = MaskFolder::truth(&fresh.root);
        assert!(truth.is_available());
        let cache = kept.view_cache.clone().expect("on");
        let (half, quarter) = (ImageScale::Factor(2), ImageScale::Factor(4));
        for index in 0..fresh.views.len() {
            // Masks alone at a scale no whole view was loaded at, then whole views (twice:
            // read, then kept), then masks at the whole views' scale.
            for round in 0..2 {
                let (camera, masks) = kept.load_view_masks(index, own.as_ref(), quarter).unwrap();
                let want = fresh.load_view_masks(index, own.as_ref(), quarter).unwrap();
                assert_eq!((camera, masks), want, "view {index} masks, round {round}");
            }
            for scale in [ImageScale::Factor(1), half] {
                for round in 0..2 {
                    let got = kept.load_view(index, scale).unwrap();
                    let want = fresh.load_view(index, scale).unwrap();
                    assert_same_view(
                        &got,
                        &want,
                        &format!("view {index} at {scale:?}, round {round}"),
                    );
                }
            }
            let got = kept.load_view_masks(index, own.as_ref(), half).unwrap();
            assert_eq!(
                got,
                fresh.load_view_masks(index, own.as_ref(), half).unwrap()
            );
            assert_eq!(
                kept.load_view_ignore(index, half).unwrap(),
                fresh.load_view_ignore(index, half).unwrap()
            );
            // Another mask source is read, never kept or served from the kept views.
            let before = cache.len();
            let got = kept.load_view_masks(index, &truth, half).unwrap();
            assert_eq!(got, fresh.load_view_masks(index, &truth, half).unwrap());
            assert_eq!(cache.len(), before, "the truth masks are not kept");
        }
        // Per view: the masks at a quarter, the whole views at full and half scale.
        assert_eq!(cache.len(), 3 * fresh.views.len());
    }
}
