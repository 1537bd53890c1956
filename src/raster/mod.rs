//! The CPU renderer (classic 3DGS / gsplat maths) and its exact backward pass.
//! Stages, one per file: project → bin (tile intersection + depth sort) → segments (which row
//! segments each intersection can touch) → rasterize forward; rasterize backward (replaying what
//! the forward stored in the segment store) → project backward. Beside them, [`reference`] is the
//! same maths written plainly, one pixel at a time, that the fast stages are tested against.
//! It must not know about files, losses or optimisers.

mod backend;
mod bin;
mod fast_exp;
mod focused;
mod forward;
mod lane_math;
mod lanes;
mod project;
mod project_backward;
mod raster_backward;
pub mod reference;
mod reference_backward;
mod segments;
#[cfg(test)]
mod tests;
pub mod weight_lift;

use std::time::{Duration, Instant};

use glam::{Vec2, Vec3, Vec4};

use crate::scene::Camera;
use crate::splats::Splats;

pub use backend::RasterBackend;
pub use bin::{tile_grid, tile_rect};
pub use focused::FrameFocus;
pub use project::camera_depths;

/// Tile edge in pixels (gsplat, 3DGS).
pub const TILE_SIZE: u32 = 16;
/// Pixels per tile.
pub(crate) const TILE_PIXELS: usize = (TILE_SIZE * TILE_SIZE) as usize;
/// Near plane: Gaussians whose camera-space depth is not above it are culled (gsplat's default
/// of [`RenderSettings::near_plane`]).
pub const NEAR_PLANE: f32 = 0.01;
/// Far plane (gsplat's default 1e10).
pub const FAR_PLANE: f32 = 1e10;
/// Most label channels the rasterizer blends (its per-tile scratch lives on the stack): the
/// model's one limit, which the PLY reader enforces.
pub const MAX_LABEL_CHANNELS: usize = crate::splats::MAX_LABEL_CHANNELS;
/// Default of [`RenderSettings::alpha_threshold`] (3DGS: 1/255).
pub const ALPHA_THRESHOLD: f32 = 1.0 / 255.0;
/// A pixel is finished once its transmittance would fall to this (3DGS, gsplat).
pub const TRANSMITTANCE_MIN: f32 = 1e-4;
/// Low-pass added to the diagonal of every 2D covariance (EWA dilation from the 3DGS paper).
pub const COV2D_BLUR: f32 = 0.3;

/// How a frame is rendered and differentiated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Composited behind the Gaussians: `C + T_final * background`.
    pub background: Vec3,
    /// Active SH degree; clamped to the model's degree.
    pub sh_degree: u32,
    /// `alpha = min(alpha_max, opacity * exp(-power))`: 0.99 in 3DGS (our default), 0.999 in gsplat.
    pub alpha_max: f32,
    /// Blending skips a Gaussian at a pixel where its alpha is below this (3DGS: 1/255). That
    /// skip is a true discontinuity of the image; finite-difference tests set 0 to remove it.
    pub alpha_threshold: f32,
    /// Whether the backward propagates colour gradients through the SH view direction into the
    /// means (the exact gradient). gsplat detaches that path; its reference tests turn this off.
    pub sh_direction_grad: bool,
    /// Gaussians whose camera-space depth is not above this are culled ([`NEAR_PLANE`] by
    /// default). A later survey's renders of the twin raise it to the view's floater clearance
    /// (`timeline::near_floaters::leaving_out_near_floaters`): that culls exactly the near floaters,
    /// bit for bit the render of the twin without them, and copies nothing. The GPU renderer
    /// keeps [`NEAR_PLANE`].
    pub near_plane: f32,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            background: Vec3::ZERO,
            sh_degree: 3,
            alpha_max: 0.99,
            alpha_threshold: ALPHA_THRESHOLD,
            sh_direction_grad: true,
            near_plane: NEAR_PLANE,
        }
    }
}

impl RenderSettings {
    pub fn new(background: Vec3, sh_degree: u32) -> Self {
        RenderSettings {
            background,
            sh_degree,
            ..Default::default()
        }
    }
}

/// A rendered frame, row-major; reused between frames and sized by [`Rasterizer::forward`].
#[derive(Clone, Debug, Default)]
pub struct RenderOutput {
    pub width: u32,
    pub height: u32,
    pub label_channels: usize,
    /// RGB interleaved, background composited: `C + T_final * background`.
    pub color: Vec<f32>,
    /// `1 - T_final`.
    pub alpha: Vec<f32>,
    /// `sum z_i alpha_i T_i` (not normalised by alpha).
    pub depth: Vec<f32>,
    /// `[pixel * label_channels + k] = sum sigmoid(raw_label_ik) alpha_i T_i`.
    pub labels: Vec<f32>,
}

/// Per-Gaussian results of projection, structure of arrays. A radius of 0 means culled; every
/// other field of a culled Gaussian is then zero.
#[derive(Clone, Debug, Default)]
pub struct Projected {
    /// Pixel coordinates of the projected mean (pixel centres at +0.5).
    pub means2d: Vec<Vec2>,
    /// Inverse of the blurred 2D covariance `(a, b, c)` = `[[a, b], [b, c]]`.
    pub conics: Vec<Vec3>,
    /// Camera-space z.
    pub depths: Vec<f32>,
    /// `ceil(3 sigma)` of the larger eigenvalue of the 2D covariance, in pixels.
    pub radii: Vec<u32>,
    /// `max(SH(dir) + 0.5, 0)`.
    pub colors: Vec<Vec3>,
    /// Bit `c` set where channel `c` passed that clamp (`SH + 0.5 >= 0`): its gradient flows
    /// back to the SH only there. Kept so the backward need not sum the SH a second time.
    pub color_pass: Vec<u8>,
    /// `sigmoid(raw_opacity)`.
    pub opacities: Vec<f32>,
    /// `sigmoid(raw_labels)`, `[g * label_channels + k]`.
    pub labels: Vec<f32>,
    /// Half-size in pixels of the axis-aligned box outside which `opacity * exp(-power)` is
    /// below the alpha threshold (with a small safety margin): no pixel outside it can be
    /// blended. Infinite when the threshold is 0.
    pub extents: Vec<Vec2>,
}

/// Per-pixel gradients of the loss with respect to a [`RenderOutput`] (same layouts).
#[derive(Clone, Copy, Debug)]
pub struct PixelGrads<'a> {
    pub color: &'a [f32],
    pub alpha: Option<&'a [f32]>,
    pub depth: Option<&'a [f32]>,
    pub labels: Option<&'a [f32]>,
}

/// Screen-space gradients of the last backward, per Gaussian (zero for culled ones).
#[derive(Clone, Debug, Default)]
pub struct ScreenGrads {
    /// In pixels.
    pub v_means2d: Vec<Vec2>,
    pub v_conics: Vec<Vec3>,
    pub v_colors: Vec<Vec3>,
    /// With respect to the activated opacity.
    pub v_opacities: Vec<f32>,
    pub v_depths: Vec<f32>,
    /// With respect to the activated labels, `[g * label_channels + k]`.
    pub v_labels: Vec<f32>,
}

/// Wall time per stage of the last forward and backward.
#[derive(Clone, Copy, Debug, Default)]
pub struct StageTimings {
    pub project: Duration,
    pub sort: Duration,
    pub raster_forward: Duration,
    pub raster_backward: Duration,
    pub project_backward: Duration,
}

/// Gradients with respect to every parameter of [`Splats`] (same layouts).
#[derive(Clone, Debug, Default)]
pub struct SplatGrads {
    pub v_means: Vec<Vec3>,
    pub v_log_scales: Vec<Vec3>,
    /// With respect to the un-normalised quaternion, glam order `(x, y, z, w)`.
    pub v_rotations: Vec<Vec4>,
    pub v_raw_opacities: Vec<f32>,
    pub v_sh: Vec<f32>,
    pub v_raw_labels: Vec<f32>,
    /// `|(v_px.x * W / 2, v_px.y * H / 2)|` for this frame: 3DGS's densification statistic.
    pub v_means2d_norm: Vec<f32>,
    /// Radius > 0 in the last forward (overwritten, not accumulated).
    pub visible: Vec<bool>,
}

impl SplatGrads {
    pub fn zeros(splats: &Splats) -> Self {
        let mut grads = SplatGrads::default();
        grads.reset(splats);
        grads
    }

    /// Resizes to `splats` and sets every gradient to zero.
    pub fn reset(&mut self, splats: &Splats) {
        let n = splats.len();
        fn fill<T: Copy>(v: &mut Vec<T>, len: usize, value: T) {
            v.clear();
            v.resize(len, value);
        }
        fill(&mut self.v_means, n, Vec3::ZERO);
        fill(&mut self.v_log_scales, n, Vec3::ZERO);
        fill(&mut self.v_rotations, n, Vec4::ZERO);
        fill(&mut self.v_raw_opacities, n, 0.0);
        fill(&mut self.v_sh, splats.sh.len(), 0.0);
        fill(&mut self.v_raw_labels, splats.raw_labels.len(), 0.0);
        fill(&mut self.v_means2d_norm, n, 0.0);
        fill(&mut self.visible, n, false);
    }
}

/// Camera constants shared by projection and its backward.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CameraFrame {
    pub world_to_camera: glam::Mat3,
    pub translation: Vec3,
    pub position: Vec3,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: u32,
    pub height: u32,
    /// gsplat's 1.3 × fov clamp of the EWA Jacobian's x / z and y / z, per side.
    pub lim_x_pos: f32,
    pub lim_x_neg: f32,
    pub lim_y_pos: f32,
    pub lim_y_neg: f32,
    /// `RenderSettings::near_plane` of the frame.
    pub near_plane: f32,
}

impl CameraFrame {
    pub fn new(camera: &Camera, settings: &RenderSettings) -> Self {
        let k = &camera.intrinsics;
        let (w, h) = (k.width as f32, k.height as f32);
        let tan_fovx = 0.5 * w / k.fx;
        let tan_fovy = 0.5 * h / k.fy;
        CameraFrame {
            world_to_camera: camera.rotation_matrix(),
            translation: camera.translation,
            position: camera.position(),
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            width: k.width,
            height: k.height,
            lim_x_pos: (w - k.cx) / k.fx + 0.3 * tan_fovx,
            lim_x_neg: k.cx / k.fx + 0.3 * tan_fovx,
            lim_y_pos: (h - k.cy) / k.fy + 0.3 * tan_fovy,
            lim_y_neg: k.cy / k.fy + 0.3 * tan_fovy,
            near_plane: settings.near_plane,
        }
    }
}

/// The CPU renderer with its scratch buffers: after the first frames of a size, forward and
/// backward allocate nothing.
#[derive(Debug, Default)]
pub struct Rasterizer {
    projected: Projected,
    bins: bin::TileBins,
    /// Tile-major blending state of the last forward: per tile `channels(L) * 256` floats.
    tile_state: Vec<f32>,
    /// What the last forward left for the backward to replay.
    segments: segments::SegmentStore,
    /// Per-intersection screen gradients of the last backward.
    isect_grads: Vec<f32>,
    /// Per-Gaussian screen gradients, `raster_backward::grad_stride(L)` floats each.
    gauss_grads: Vec<f32>,
    screen: ScreenGrads,
    timings: StageTimings,
    label_channels: usize,
    width: u32,
    height: u32,
    /// Focused runs' per-view caches of the frozen Gaussians (`focused.rs`).
    focus: focused::FocusState,
}

impl Rasterizer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Renders `splats` from `camera` into `out` and keeps what the backward needs.
    pub fn forward(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        out: &mut RenderOutput,
    ) {
        if self.forward_cached(splats, camera, settings, out).is_none() {
            self.forward_whole(splats, camera, settings, out);
        }
    }

    /// `forward` of every Gaussian, no cache.
    fn forward_whole(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        out: &mut RenderOutput,
    ) {
        self.focus.forget_written();
        let labels = splats.label_channels;
        assert!(
            labels <= MAX_LABEL_CHANNELS,
            "{labels} label channels; the rasterizer blends at most {MAX_LABEL_CHANNELS}"
        );
        let frame = CameraFrame::new(camera, settings);
        self.label_channels = labels;
        self.width = frame.width;
        self.height = frame.height;

        let t0 = Instant::now();
        project::project(splats, &frame, settings, &mut self.projected);
        let t1 = Instant::now();
        self.bins.build(&self.projected, frame.width, frame.height);
        let t2 = Instant::now();
        self.rasterize_bins(settings, labels, &frame, out);
        let t3 = Instant::now();
        self.timings.project = t1 - t0;
        self.timings.sort = t2 - t1;
        self.timings.raster_forward = t3 - t2;
    }

    /// Blends the binned frame into `out` (the forward after binning).
    fn rasterize_bins(
        &mut self,
        settings: &RenderSettings,
        labels: usize,
        frame: &CameraFrame,
        out: &mut RenderOutput,
    ) {
        forward::rasterize(
            &self.projected,
            &self.bins,
            labels,
            settings,
            &mut self.tile_state,
            &mut self.segments,
        );
        forward::write_output(
            &self.tile_state,
            &self.bins,
            labels,
            settings.background,
            frame.width,
            frame.height,
            out,
        );
    }

    /// Renders only these tiles (`ty * tiles_x + tx`, one flag per tile of the next frames;
    /// None: all). The others come out as background and take no part in the backward: a
    /// refinement whose loss lives inside hull masks pays only for the tiles they touch. A mask
    /// of the wrong length for a frame is ignored.
    pub fn set_active_tiles(&mut self, tiles: Option<&[bool]>) {
        match tiles {
            Some(t) => {
                let active = self.bins.active.get_or_insert_with(Vec::new);
                active.clear();
                active.extend_from_slice(t);
            }
            None => self.bins.active = None,
        }
    }

    /// Renders only these pixels of the active tiles (None: all), as [`pixel_rows`] packs a
    /// mask: the others come out as background, blend nothing and take no part in the
    /// backward, so a refinement pays per hull pixel, not per 16×16 tile. Every rendered
    /// pixel and every gradient from them is bit-identical to a frame without the mask. Rows
    /// of the wrong length for a frame are ignored.
    pub fn set_active_pixels(&mut self, rows: Option<&[u16]>) {
        match rows {
            Some(r) => {
                let active = self.bins.active_pixels.get_or_insert_with(Vec::new);
                active.clear();
                active.extend_from_slice(r);
            }
            None => self.bins.active_pixels = None,
        }
    }

    pub fn projected(&self) -> &Projected {
        &self.projected
    }

    /// Sorted intersections of the last forward: the Gaussian index per intersection, ordered
    /// by (tile, depth), and per tile (`ty * tiles_x + tx`) its `[start, end)` range.
    pub fn tile_bins(&self) -> (&[u32], &[[u32; 2]]) {
        (&self.bins.gaussian_ids, &self.bins.tile_ranges)
    }

    pub fn screen_grads(&self) -> &ScreenGrads {
        &self.screen
    }

    pub fn timings(&self) -> &StageTimings {
        &self.timings
    }

    /// Backward of the last forward (same splats, camera and settings). Every gradient in
    /// `grads` is overwritten (resized to `splats` first when it does not fit), as is
    /// `grads.visible`.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        v_color: &[f32],
        v_alpha: Option<&[f32]>,
        v_labels: Option<&[f32]>,
        grads: &mut SplatGrads,
    ) {
        let v_out = PixelGrads {
            color: v_color,
            alpha: v_alpha,
            depth: None,
            labels: v_labels,
        };
        self.backward_pixels(splats, camera, settings, &v_out, grads);
    }

    /// [`Rasterizer::backward`] with an optional depth gradient.
    pub fn backward_pixels(
        &mut self,
        splats: &Splats,
        camera: &Camera,
        settings: &RenderSettings,
        v_out: &PixelGrads,
        grads: &mut SplatGrads,
    ) {
        let n = splats.len();
        assert_eq!(
            self.projected.radii.len(),
            n,
            "backward needs the forward of the same splats"
        );
        // In `usize`: the `u32` product wraps past 65536 × 65536.
        let pixels = self.width as usize * self.height as usize;
        assert_eq!(v_out.color.len(), pixels * 3, "v_color has the wrong size");
        if grads.v_means.len() != n
            || grads.v_sh.len() != splats.sh.len()
            || grads.v_raw_labels.len() != splats.raw_labels.len()
        {
            grads.reset(splats);
        }
        let frame = CameraFrame::new(camera, settings);
        if self.focus.last_cached() {
            self.backward_cached(splats, &frame, settings, v_out, grads);
            return;
        }
        let t0 = Instant::now();
        self.blend_backward(settings, v_out);
        raster_backward::unpack_screen_grads(
            &self.gauss_grads,
            n,
            self.label_channels,
            &mut self.screen,
        );
        let t1 = Instant::now();
        project_backward::project_backward(
            splats,
            &frame,
            settings,
            &self.projected,
            &self.screen,
            grads,
        );
        let t2 = Instant::now();
        self.timings.raster_backward = t1 - t0;
        self.timings.project_backward = t2 - t1;
    }

    /// The blending's backward over the last frame's tile lists into per-intersection and
    /// per-Gaussian screen gradients: the same for a whole frame and a cached focused one.
    fn blend_backward(&mut self, settings: &RenderSettings, v_out: &PixelGrads) {
        raster_backward::rasterize_backward(
            &self.projected,
            &self.bins,
            &self.tile_state,
            &self.segments,
            self.label_channels,
            settings,
            v_out,
            self.width,
            self.height,
            &mut self.isect_grads,
            &mut self.gauss_grads,
        );
    }
}

/// A `width × height` row-major mask (non-zero: rendered) packed as
/// [`Rasterizer::set_active_pixels`] reads it: per tile (`ty * tiles_x + tx`) 16 rows, bit `x`
/// of row `y` for the tile's pixel `(x, y)`; pixels past the image are left out.
pub fn pixel_rows(mask: &[u8], width: u32, height: u32) -> Vec<u16> {
    let ts = TILE_SIZE as usize;
    let (tiles_x, tiles_y) = tile_grid(width, height);
    let (w, tiles_x) = (width as usize, tiles_x as usize);
    let mut rows = vec![0u16; tiles_x * tiles_y as usize * ts];
    if w == 0 {
        return rows;
    }
    for (y, row) in mask.chunks_exact(w).take(height as usize).enumerate() {
        let (ty, iy) = (y / ts, y % ts);
        for (x, &m) in row.iter().enumerate() {
            if m != 0 {
                rows[(ty * tiles_x + x / ts) * ts + iy] |= 1 << (x % ts);
            }
        }
    }
    rows
}

/// Convenience: renders one frame with a fresh [`Rasterizer`].
pub fn render(splats: &Splats, camera: &Camera, settings: &RenderSettings) -> RenderOutput {
    let mut out = RenderOutput::default();
    Rasterizer::new().forward(splats, camera, settings, &mut out);
    out
}
