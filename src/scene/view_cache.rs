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
