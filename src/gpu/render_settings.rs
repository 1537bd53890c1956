//! The GPU renderer's options, apart from the renderer so the stages (`project`, …) that read
//! them need not look up to it.

use glam::Vec3;

use crate::raster::RenderSettings;

/// Render options (the GPU twin of `raster::RenderSettings`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuRenderSettings {
    /// Composited behind the splats: `C + T_final · background`.
    pub background: Vec3,
    /// Active SH degree; clamped to the model's.
    pub sh_degree: u32,
    /// `alpha = min(alpha_max, opacity · exp(-power))`: 0.99 in 3DGS (default), 0.999 in gsplat.
    pub alpha_max: f32,
    /// Backward only (see `raster::RenderSettings::sh_direction_grad`).
    pub sh_direction_grad: bool,
}

impl Default for GpuRenderSettings {
    fn default() -> Self {
        GpuRenderSettings::from(&RenderSettings::default())
    }
}

impl From<&RenderSettings> for GpuRenderSettings {
    /// The forward part of the CPU settings (the backward-only options do not apply).
    fn from(s: &RenderSettings) -> Self {
        GpuRenderSettings {
            background: s.background,
            sh_degree: s.sh_degree,
            alpha_max: s.alpha_max,
            sh_direction_grad: s.sh_direction_grad,
        }
    }
}
