//! Focused frames: a run in which only a few Gaussians change (a refinement, a survey update)
//! renders each view many times with the rest of the model frozen. The frozen Gaussians'
//! projection and per-tile depth order in a view do not change between those frames, so the
//! first frame of a view is rendered whole and leaves them in that view's cache; later frames
//! project only the trainable Gaussians, bin and sort only them, and merge them per tile into
//! the cached frozen lists in (depth, index) order. The backward differentiates only the
//! trainable Gaussians' projection. The bins are those a whole frame makes, so the image and
//! the trainable Gaussians' gradients are bit-identical to the plain path's.
//!
//! A cache is used only under the key it was built with: the same camera, render settings,
//! active tiles, Gaussian count, trainable set and `generation`, a number the caller changes
//! whenever a frozen Gaussian's parameters may have changed.

use std::time::Instant;

use super::bin::FrozenTiles;
use super::{
    CameraFrame, PixelGrads, Projected, Rasterizer, RenderOutput, RenderSettings, ScreenGrads,
    SplatGrads, project, project_backward, raster_backward,
};
use crate::scene::Camera;
use crate::splats::Splats;

/// What the next frames of a focused run are (`Rasterizer::set_focus`).
#[derive(Clone, Copy, Debug)]
pub struct FrameFocus<'a> {
    /// Ascending indices of the Gaussians that may change between frames; every other one is
    /// frozen.
    pub trainable: &'a [u32],
    /// The view rendered (the caller's index): frames of one view share its frozen cache.
    pub view: usize,
    /// Changed by the caller whenever a frozen Gaussian's parameters may have changed (a
    /// density change, colours folded, a checkpoint restored): every cache of another
    /// generation is rebuilt.
    pub generation: u64,
}

/// What a view's frozen cache was built under: it serves only frames that match.
#[derive(Clone, Debug, PartialEq)]
struct FrozenKey {
    generation: u64,
    gaussians: usize,
    camera: Camera,
    settings: RenderSettings,
    active: Option<Vec<bool>>,
}

/// One view's frozen Gaussians as a whole frame of it projected and binned them.
#[derive(Debug, Default)]
struct FrozenView {
    key: Option<FrozenKey>,
    /// The frozen Gaussians binned into a tile of the frame, ascending.
    ids: Vec<u32>,
    /// Their projection, in `ids` order.
    projected: Projected,
    /// Per tile its `[start, end)` range in `tile_ids`, ordered by depth then index.
    tile_ranges: Vec<[u32; 2]>,
    tile_ids: Vec<u32>,
}

/// The rasterizer's focused-run state.
#[derive(Debug, Default)]
pub(crate) struct FocusState {
    /// The focus of the next frames (None: plain frames).
    view: Option<usize>,
    generation: u64,
    trainable: Vec<u32>,
    is_trainable: Vec<bool>,
    views: Vec<FrozenView>,
    /// Set when the last forward took the cached path: its backward must too.
    last_cached: bool,
    /// Which entries of `Rasterizer::projected` the last cached frame wrote (trainable, and
    /// that view's frozen ones); None after a whole frame, which wrote every entry.
    written_view: Option<usize>,
    /// The trainable Gaussians gathered, their projection, screen and parameter gradients.
    sub: Splats,
    sub_projected: Projected,
    sub_screen: ScreenGrads,
    sub_grads: SplatGrads,
}

impl FocusState {
    /// Takes the next frames' focus; a new trainable set drops every cache.
    pub fn set(&mut self, focus: Option<FrameFocus<'_>>) {
        let Some(f) = focus else {
            self.view = None;
            return;
        };
        if f.trainable != self.trainable.as_slice() || f.generation != self.generation {
            self.trainable.clear();
            self.trainable.extend_from_slice(f.trainable);
            self.generation = f.generation;
            for view in &mut self.views {
                view.key = None;
            }
        }
        if self.views.len() <= f.view {
            self.views.resize_with(f.view + 1, FrozenView::default);
        }
        self.view = Some(f.view);
    }

    /// A whole frame writes every entry of `projected` and is differentiated whole.
    pub fn forget_written(&mut self) {
        self.written_view = None;
        self.last_cached = false;
    }

    pub fn last_cached(&self) -> bool {
        self.last_cached
    }

    /// The key a cache must have to serve a frame of `splats` from `camera` with `settings`
    /// and the active tiles `active`.
    fn key_for(
        &self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        active: Option<&[bool]>,
    ) -> FrozenKey {
        FrozenKey {
            generation: self.generation,
            gaussians: splats.len(),
            camera: *camera,
            settings: *settings,
            active: active.map(<[bool]>::to_vec),
        }
    }
}

/// Copies entry `j` of `src` into entry `g` of `dst` (label channels `l`).
fn copy_entry(dst: &mut Projected, g: usize, src: &Projected, j: usize, l: usize) {
    dst.means2d[g] = src.means2d[j];
    dst.conics[g] = src.conics[j];
    dst.depths[g] = src.depths[j];
    dst.radii[g] = src.radii[j];
    dst.colors[g] = src.colors[j];
    dst.color_pass[g] = src.color_pass[j];
    dst.opacities[g] = src.opacities[j];
    dst.extents[g] = src.extents[j];
    dst.labels[g * l..(g + 1) * l].copy_from_slice(&src.labels[j * l..(j + 1) * l]);
}

/// Entry `g` of `p` as a culled Gaussian's: every field zero.
fn cull_entry(p: &mut Projected, g: usize, l: usize) {
    p.means2d[g] = Default::default();
    p.conics[g] = Default::default();
    p.depths[g] = 0.0;
    p.radii[g] = 0;
    p.colors[g] = Default::default();
    p.color_pass[g] = 0;
    p.opacities[g] = 0.0;
    p.extents[g] = Default::default();
    p.labels[g * l..(g + 1) * l].fill(0.0);
}

/// `p` resized to `n` culled entries.
fn all_culled(p: &mut Projected, n: usize, l: usize) {
    fn fill<T: Copy + Default>(v: &mut Vec<T>, n: usize) {
        v.clear();
        v.resize(n, T::default());
    }
    fill(&mut p.means2d, n);
    fill(&mut p.conics, n);
    fill(&mut p.depths, n);
    fill(&mut p.radii, n);
    fill(&mut p.colors, n);
    fill(&mut p.color_pass, n);
    fill(&mut p.opacities, n);
    fill(&mut p.extents, n);
    fill(&mut p.labels, n * l);
}

/// The Gaussians `ids` of `splats` as a model of their own (parameters only).
fn gather_subset(splats: &Splats, ids: &[u32], sub: &mut Splats) {
    let k = splats.sh_coeffs() * 3;
    let l = splats.label_channels;
    sub.sh_degree = splats.sh_degree;
    sub.label_channels = l;
    sub.means.clear();
    sub.log_scales.clear();
    sub.rotations.clear();
    sub.raw_opacities.clear();
    sub.sh.clear();
    sub.raw_labels.clear();
    for &g in ids {
        let g = g as usize;
        sub.means.push(splats.means[g]);
        sub.log_scales.push(splats.log_scales[g]);
        sub.rotations.push(splats.rotations[g]);
        sub.raw_opacities.push(splats.raw_opacities[g]);
        sub.sh.extend_from_slice(&splats.sh[g * k..(g + 1) * k]);
        sub.raw_labels
            .extend_from_slice(&splats.raw_labels[g * l..(g + 1) * l]);
    }
}

impl Rasterizer {
    /// Renders the next frames as frames of a focused run (None: plain frames): see the
    /// module `focused`. The first frame of each view, and every frame after the focus's
    /// trainable set, generation, the camera, settings, active tiles or Gaussian count changed,
    /// is rendered whole and refills that view's cache. After a cached frame, `projected`
    /// holds only the Gaussians the frame binned (the others read as culled), `screen_grads`
    /// only the trainable ones' (in `trainable` order), and the backward writes gradients for
    /// the trainable Gaussians only (the frozen ones' are zero).
    pub fn set_focus(&mut self, focus: Option<FrameFocus<'_>>) {
        self.focus.set(focus);
    }

    /// Whether the last forward reused a frozen cache.
    pub fn last_frame_cached(&self) -> bool {
        self.focus.last_cached
    }

    /// The forward of a focused frame, or None to render it whole.
    pub(super) fn forward_cached(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        out: &mut RenderOutput,
    ) -> Option<()> {
        let view = self.focus.view?;
        let active = self.bins.active.as_deref();
        let key = self.focus.key_for(splats, camera, settings, active);
        if self.focus.views[view].key.as_ref() != Some(&key) {
            // Whole frame, then its frozen part kept.
            self.forward_whole(splats, camera, settings, out);
            self.keep_frozen(view, key);
            return Some(());
        }
        let frame = CameraFrame::new(camera, settings);
        let labels = splats.label_channels;
        let n = splats.len();
        let t0 = Instant::now();
        let f = &mut self.focus;
        gather_subset(splats, &f.trainable, &mut f.sub);
        project::project(&f.sub, &frame, settings, &mut f.sub_projected);
        // Entries the last cached frame wrote go back to culled; after a whole frame, all.
        match f.written_view {
            Some(last) if self.projected.radii.len() == n => {
                for &g in &f.views[last].ids {
                    cull_entry(&mut self.projected, g as usize, labels);
                }
            }
            _ => all_culled(&mut self.projected, n, labels),
        }
        for (j, &g) in f.trainable.iter().enumerate() {
            copy_entry(&mut self.projected, g as usize, &f.sub_projected, j, labels);
        }
        f.written_view = Some(view);
        f.last_cached = true;
        let cache = &f.views[view];
        for (j, &g) in cache.ids.iter().enumerate() {
            copy_entry(&mut self.projected, g as usize, &cache.projected, j, labels);
        }
        let t1 = Instant::now();
        self.bins.build_merged(
            &self.projected,
            frame.width,
            frame.height,
            &f.trainable,
            FrozenTiles {
                ranges: &cache.tile_ranges,
                ids: &cache.tile_ids,
            },
        );
        let t2 = Instant::now();
        self.label_channels = labels;
        self.width = frame.width;
        self.height = frame.height;
        self.rasterize_bins(settings, labels, &frame, out);
        let t3 = Instant::now();
        self.timings.project = t1 - t0;
        self.timings.sort = t2 - t1;
        self.timings.raster_forward = t3 - t2;
        Some(())
    }

    /// Keeps the frozen part of the whole frame just rendered as `view`'s cache.
    fn keep_frozen(&mut self, view: usize, key: FrozenKey) {
        let f = &mut self.focus;
        let n = key.gaussians;
        f.is_trainable.clear();
        f.is_trainable.resize(n, false);
        for &g in &f.trainable {
            if let Some(t) = f.is_trainable.get_mut(g as usize) {
                *t = true;
            }
        }
        let l = self.label_channels;
        let cache = &mut f.views[view];
        cache.tile_ranges.clear();
        cache.tile_ids.clear();
        let mut binned = vec![false; n];
        for [start, end] in &self.bins.tile_ranges {
            let from = cache.tile_ids.len() as u32;
            for &g in &self.bins.gaussian_ids[*start as usize..*end as usize] {
                if !f.is_trainable[g as usize] {
                    cache.tile_ids.push(g);
                    binned[g as usize] = true;
                }
            }
            cache.tile_ranges.push([from, cache.tile_ids.len() as u32]);
        }
        cache.ids.clear();
        cache.ids.extend(
            binned
                .iter()
                .enumerate()
                .filter(|(_, b)| **b)
                .map(|(g, _)| g as u32),
        );
        all_culled(&mut cache.projected, cache.ids.len(), l);
        for (j, &g) in cache.ids.iter().enumerate() {
            copy_entry(&mut cache.projected, j, &self.projected, g as usize, l);
        }
        cache.key = Some(key);
    }

    /// The backward of a cached frame: the blending's as always, then the projection's of the
    /// trainable Gaussians only.
    pub(super) fn backward_cached(
        &mut self,
        splats: &Splats,
        frame: &CameraFrame,
        settings: &RenderSettings,
        v_out: &PixelGrads,
        grads: &mut SplatGrads,
    ) {
        let t0 = Instant::now();
        self.blend_backward(settings, v_out);
        let f = &mut self.focus;
        raster_backward::unpack_screen_grads_of(
            &self.gauss_grads,
            &f.trainable,
            self.label_channels,
            &mut f.sub_screen,
        );
        let t1 = Instant::now();
        f.sub_grads.reset(&f.sub);
        project_backward::project_backward(
            &f.sub,
            frame,
            settings,
            &f.sub_projected,
            &f.sub_screen,
            &mut f.sub_grads,
        );
        grads.reset(splats);
        scatter_grads(&f.sub_grads, &f.trainable, splats, grads);
        let t2 = Instant::now();
        self.timings.raster_backward = t1 - t0;
        self.timings.project_backward = t2 - t1;
    }
}

/// The gradients of the Gaussians `ids` (`sub`, in `ids` order) into `grads` at their indices.
fn scatter_grads(sub: &SplatGrads, ids: &[u32], splats: &Splats, grads: &mut SplatGrads) {
    let k = splats.sh_coeffs() * 3;
    let l = splats.label_channels;
    for (j, &g) in ids.iter().enumerate() {
        let g = g as usize;
        grads.v_means[g] = sub.v_means[j];
        grads.v_log_scales[g] = sub.v_log_scales[j];
        grads.v_rotations[g] = sub.v_rotations[j];
        grads.v_raw_opacities[g] = sub.v_raw_opacities[j];
        grads.v_sh[g * k..(g + 1) * k].copy_from_slice(&sub.v_sh[j * k..(j + 1) * k]);
        grads.v_raw_labels[g * l..(g + 1) * l]
            .copy_from_slice(&sub.v_raw_labels[j * l..(j + 1) * l]);
        grads.v_means2d_norm[g] = sub.v_means2d_norm[j];
        grads.visible[g] = sub.visible[j];
    }
}
