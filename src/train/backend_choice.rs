//! Which renderer a run trains on (`--backend cpu|gpu|auto`): the CPU rasterizer (the reference,
//! the default), the GPU through wgpu (`gpu::GpuBackend`), or the GPU when a hardware adapter
//! exists and the CPU otherwise (a software Vulkan driver is slower than the CPU rasterizer).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::gpu::{GpuBackend, GpuContext, GpuError};
use crate::raster::{RasterBackend, Rasterizer};

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    #[default]
    Cpu,
    Gpu,
    Auto,
}

impl FromStr for Backend {
    type Err = String;

    fn from_str(s: &str) -> Result<Backend, String> {
        match s {
            "cpu" => Ok(Backend::Cpu),
            "gpu" => Ok(Backend::Gpu),
            "auto" => Ok(Backend::Auto),
            other => Err(format!("unknown backend `{other}` (cpu, gpu or auto)")),
        }
    }
}

impl fmt::Display for Backend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Backend::Cpu => "cpu",
            Backend::Gpu => "gpu",
            Backend::Auto => "auto",
        })
    }
}

/// The renderer for `choice` and one line saying what it is. `Gpu` fails without an adapter;
/// `Auto` falls back to the CPU without a hardware one.
pub fn open_backend(choice: Backend) -> Result<(Box<dyn RasterBackend>, String), GpuError> {
    let cpu = || -> (Box<dyn RasterBackend>, String) {
        (Box::new(Rasterizer::new()), "CPU rasterizer".to_string())
    };
    match choice {
        Backend::Cpu => Ok(cpu()),
        Backend::Gpu => gpu(GpuContext::new()?),
        Backend::Auto => match GpuContext::new_hardware() {
            Ok(Some(ctx)) => gpu(ctx),
            _ => Ok(cpu()),
        },
    }
}

fn gpu(ctx: GpuContext) -> Result<(Box<dyn RasterBackend>, String), GpuError> {
    let backend = GpuBackend::new(&ctx)?;
    let what = format!("GPU: {}", backend.describe());
    Ok((Box::new(backend), what))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_prints_the_three_choices() {
        for b in [Backend::Cpu, Backend::Gpu, Backend::Auto] {
            assert_eq!(b.to_string().parse::<Backend>(), Ok(b));
        }
        assert!(
            "cuda"
                .parse::<Backend>()
                .unwrap_err()
                .contains("cpu, gpu or auto")
        );
    }
}
