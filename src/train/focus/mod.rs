//! A focused run: a few Gaussians of a trained model trained on crops of its views, every other
//! Gaussian frozen but still rendered, so a step costs what the crops cost. The seam says which
//! Gaussians train and how (`gaussians`: the spec, and the result's trained or created Gaussians
//! found again by id), which views at what scale, each photo in the model's light
//! (`ViewLights`), and where in each view: the hulls of the trained Gaussians (`hulls`), cropped
//! with a margin of context. Refinement is "select damage → focus → train"; the targeted update
//! of a later survey is the same with that survey's photos and their lights.

pub mod gaussians;
pub mod hulls;

use std::collections::BTreeMap;

use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;

pub use gaussians::{Strategy, continue_trained, focused_spec, trained_or_created};
use hulls::{Hull, HullConfig, union_mask, view_hulls};

use crate::raster::RenderSettings;
use crate::raster::weight_lift::WeightLift;
use crate::scene::project::ColourTransform;
use crate::scene::{Dataset, ImageScale, Mask, SceneError};
use crate::splats::Splats;
use crate::train::spec::TrainView;
use crate::train::views::load_views;

/// Per dataset view index, how its photo's light differs from the model's
/// (`TrainView::light`); views without one are in the model's light.
pub type ViewLights = BTreeMap<usize, ColourTransform>;

/// Hulls of one view.
#[derive(Clone, Debug, Serialize)]
pub struct ViewHulls {
    pub view: String,
    pub index: usize,
    pub heldout: bool,
    pub width: u32,
    pub height: u32,
    #[serde(skip)]
    pub hulls: Vec<Hull>,
    pub hull_count: usize,
    /// Pixels inside any hull.
    pub pixels: usize,
}

impl ViewHulls {
    pub fn union(&self) -> Mask {
        union_mask(&self.hulls, self.width, self.height)
    }
}

/// Where a focused run's views come from and how they are cut: a dataset's views at one scale,
/// each photo with its light, cropped to its hulls with a margin of context.
#[derive(Clone, Copy, Debug)]
pub struct Focus<'a> {
    pub dataset: &'a Dataset,
    /// The scale the hulls are drawn and the views loaded at.
    pub scale: ImageScale,
    pub lights: &'a ViewLights,
    /// Pixels of context kept around a view's hulls in its crop.
    pub margin_px: u32,
}

impl Focus<'_> {
    /// The hulls of `model`'s Gaussians `gaussians` (`region_of[i]` the region of
    /// `gaussians[i]`) in each of `views` (dataset index, held out), telling `progress` each
    /// view drawn.
    #[allow(clippy::too_many_arguments)]
    pub fn draw_hulls(
        &self,
        model: &Splats,
        gaussians: &[u32],
        region_of: &[u32],
        views: &[(usize, bool)],
        config: &HullConfig,
        background: Vec3,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<Vec<ViewHulls>, SceneError> {
        let settings = RenderSettings::new(background, model.sh_degree);
        let mut lift = WeightLift::new(model, 1, settings);
        let mut drawn = Vec::with_capacity(views.len());
        for (done, &(index, heldout)) in views.iter().enumerate() {
            let camera = self.dataset.view_camera(index, self.scale)?;
            // Only the tiles the set is binned into: its weights are those of the whole
            // render, bit for bit, at a fraction of its cost (`WeightLift::view_of`).
            let weights = lift.view_of(&camera, gaussians, |_, _| 1.0);
            // Visible: draws at least a tenth of a pixel's worth in this view (read only for
            // the set's Gaussians).
            let visible: Vec<bool> = weights.iter().map(|&w| w > 0.1).collect();
            let projected = lift.projected();
            let k = camera.intrinsics;
            let hulls = view_hulls(
                projected, &visible, gaussians, region_of, config, k.width, k.height,
            );
            let pixels = union_mask(&hulls, k.width, k.height).count();
            drawn.push(ViewHulls {
                view: self.dataset.views[index].name.clone(),
                index,
                heldout,
                width: k.width,
                height: k.height,
                hull_count: hulls.len(),
                hulls,
                pixels,
            });
            progress(done + 1, views.len());
        }
        Ok(drawn)
    }

    /// Views `indices` whole at the focus's scale (with their damage masks when `labels`), each
    /// photo mapped into the model's light, then made into training targets by `targets`.
    pub fn load(
        &self,
        indices: &[usize],
        labels: bool,
        targets: &(dyn Fn(&mut [TrainView]) + Sync),
    ) -> Result<Vec<TrainView>, SceneError> {
        let mut views = load_views(self.dataset, indices, self.scale, labels)?;
        for (view, index) in views.iter_mut().zip(indices) {
            view.light = self.lights.get(index).copied();
            view.to_model_light();
        }
        targets(&mut views);
        Ok(views)
    }

    /// The training views of `regions`: each view loaded as `load` loads it and cropped to its
    /// hulls (`crop_to_hulls`), in parallel.
    pub fn load_crops(
        &self,
        regions: &[&ViewHulls],
        labels: bool,
        targets: &(dyn Fn(&mut [TrainView]) + Sync),
    ) -> Result<Vec<TrainView>, SceneError> {
        regions
            .par_iter()
            .map(|v| {
                let mut loaded = self.load(&[v.index], labels, targets)?;
                let full = loaded.pop().expect("one view loaded");
                Ok(crop_to_hulls(&full, &v.hulls, self.margin_px))
            })
            .collect()
    }
}

/// The training view of one view's hulls: the box around all of them plus a margin, cropped
/// from the full view, with their union (in crop coordinates) as the loss region. The trainer
/// renders only the tiles that region needs, so the step costs what the hulls cost.
pub fn crop_to_hulls(full: &TrainView, hulls: &[Hull], margin: u32) -> TrainView {
    let k = full.camera.intrinsics;
    let (mut x0, mut y0, mut x1, mut y1) = (k.width, k.height, 0, 0);
    for hull in hulls {
        x0 = x0.min(hull.x0);
        y0 = y0.min(hull.y0);
        x1 = x1.max(hull.x0 + hull.mask.width);
        y1 = y1.max(hull.y0 + hull.mask.height);
    }
    let (x0, y0) = (x0.saturating_sub(margin), y0.saturating_sub(margin));
    let (x1, y1) = ((x1 + margin).min(k.width), (y1 + margin).min(k.height));
    let (w, h) = (x1.saturating_sub(x0).max(1), y1.saturating_sub(y0).max(1));
    let mut region = union_mask(hulls, k.width, k.height).crop(x0, y0, w, h);
    // Inside the hulls, the view's ignored pixels stay ignored.
    if let Some(used) = &full.region {
        let used = used.crop(x0, y0, w, h);
        for (r, u) in region.data.iter_mut().zip(&used.data) {
            *r &= u;
        }
    }
    TrainView {
        name: full.name.clone(),
        camera: full.camera.cropped(x0, y0, w, h),
        image: full.image.crop(x0, y0, w, h),
        labels: full.labels.iter().map(|m| m.crop(x0, y0, w, h)).collect(),
        region: Some(region),
        light: full.light,
    }
}
