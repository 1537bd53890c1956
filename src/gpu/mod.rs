//! The GPU renderer: wgpu compute kernels (`shaders/*.wgsl`) doing the same stages as the CPU
//! reference in `raster` (project, sort, tile ranges, rasterize, and the backward of rasterize and
//! project), each tested against it. Host launch code lives here, one file per stage; no UI code.
//! The viewer's forward never reads back; the trainer's backend ([`GpuBackend`]) does, per step.

pub mod adam;
pub mod backward;
pub mod context;
mod count_probe;
pub mod emit;
mod frame_buffers;
pub mod kernel;
pub mod loss;
pub mod prefix_sum;
pub mod project;
pub mod radix_sort;
pub mod rasterize;
pub mod readback;
pub mod render_settings;
pub mod renderer;
pub mod select;
pub mod splat_buffers;
pub mod tile_ranges;
pub mod timing;
pub mod train_backend;

pub use context::{GpuCapabilities, GpuContext};
pub use render_settings::GpuRenderSettings;
pub use renderer::{GpuFrame, GpuRenderer};
pub use splat_buffers::SplatBuffers;
pub use train_backend::{GpuBackend, StepProfile};

/// Errors at the GPU module's edge.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found: install a GPU driver, or Mesa's software Vulkan driver \
         (Debian/Ubuntu package `mesa-vulkan-drivers`, plus `libvulkan1`)"
    )]
    NoAdapter,
    #[error("creating the GPU device failed: {0}")]
    Device(String),
    #[error("{what} needs {needed} bytes in one buffer, the adapter allows {limit}")]
    TooLarge {
        what: &'static str,
        needed: u64,
        limit: u64,
    },
    #[error("the GPU renderer supports at most {max} label channels, the model has {got}")]
    TooManyLabels { max: usize, got: usize },
    #[error("invalid camera: {0}")]
    InvalidCamera(String),
    #[error("invalid splats: {0}")]
    InvalidSplats(String),
    #[error("reading a GPU buffer back failed: {0}")]
    Readback(String),
}
