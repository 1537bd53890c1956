//! The seam between the trainer and a renderer: forward a model from a camera, then the exact
//! backward of that frame. The CPU `Rasterizer` is the reference implementation; a GPU backend
//! implements the same trait, so the trainer's schedule, losses, densification and job are the
//! same whichever renders.

use super::{PixelGrads, Rasterizer, RenderOutput, RenderSettings, SplatGrads, StageTimings};
use crate::scene::Camera;
use crate::splats::Splats;

/// A differentiable renderer the trainer can drive.
pub trait RasterBackend: Send {
    /// A short name for logs and benchmarks (`"cpu"`, `"gpu"`).
    fn name(&self) -> &'static str;

    /// Renders `splats` from `camera` into `out` (resized as needed) and keeps what the
    /// backward needs.
    fn forward(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        out: &mut RenderOutput,
    );

    /// The backward of the last forward (same splats, camera and settings): every gradient in
    /// `grads` is overwritten, `grads.visible` and `grads.v_means2d_norm` included.
    fn backward(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        v_out: &PixelGrads,
        grads: &mut SplatGrads,
    );

    /// Renders only these tiles in the next frames (None: all); see
    /// `Rasterizer::set_active_tiles`. Rendering every tile is always correct, only slower, so
    /// a backend may ignore this.
    fn set_active_tiles(&mut self, tiles: Option<&[bool]>) {
        let _ = tiles;
    }

    /// Renders only these pixels of the active tiles in the next frames (None: all); see
    /// `Rasterizer::set_active_pixels`. Rendering every pixel is always correct, only slower,
    /// so a backend may ignore this.
    fn set_active_pixels(&mut self, rows: Option<&[u16]>) {
        let _ = rows;
    }

    /// The focus of the next frames of a focused run (None: plain frames); see
    /// `Rasterizer::set_focus`. Rendering every frame whole is always correct, only slower, so
    /// a backend may ignore this.
    fn set_focus(&mut self, focus: Option<super::FrameFocus<'_>>) {
        let _ = focus;
    }

    /// Per Gaussian, the screen radius of the last forward (0: culled); density control
    /// reads it.
    fn radii(&self) -> &[u32];

    /// Wall time per stage of the last forward and backward.
    fn timings(&self) -> StageTimings;

    /// Why the renderer stopped working (a lost GPU device), if it did: the frames since are
    /// zero and the run must end. The CPU rasterizer never fails.
    fn fault(&self) -> Option<&str> {
        None
    }

    /// The backend as `Any`, for a trainer that drives a known backend beyond this trait (the
    /// GPU backend keeps the model and optimiser on the device). None: only this trait.
    fn as_any_mut(&mut self) -> Option<&mut dyn std::any::Any> {
        None
    }
}

impl RasterBackend for Rasterizer {
    fn name(&self) -> &'static str {
        "cpu"
    }

    fn forward(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        out: &mut RenderOutput,
    ) {
        Rasterizer::forward(self, splats, camera, settings, out);
    }

    fn backward(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        v_out: &PixelGrads,
        grads: &mut SplatGrads,
    ) {
        self.backward_pixels(splats, camera, settings, v_out, grads);
    }

    fn set_active_tiles(&mut self, tiles: Option<&[bool]>) {
        Rasterizer::set_active_tiles(self, tiles);
    }

    fn set_active_pixels(&mut self, rows: Option<&[u16]>) {
        Rasterizer::set_active_pixels(self, rows);
    }

    fn set_focus(&mut self, focus: Option<super::FrameFocus<'_>>) {
        Rasterizer::set_focus(self, focus);
    }

    fn radii(&self) -> &[u32] {
        &self.projected().radii
    }

    fn timings(&self) -> StageTimings {
        *Rasterizer::timings(self)
    }
}
