//! The wgpu device every GPU stage runs on: adapter choice (a real GPU first, Mesa's lavapipe as
//! the fallback), the limits and optional features it was created with, or a device borrowed from
//! eframe. It must not hold per-scene state (buffers live in the stages and the renderer).

use std::sync::Arc;

use super::GpuError;

/// Optional features the adapter offers. The forward pass uses none of them (every kernel has a
/// portable path); they are recorded so callers (the bench, the future GPU backward) can choose.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct GpuCapabilities {
    /// `atomicAdd` on `f32` in storage buffers (gradient accumulation without CAS loops).
    pub float32_atomics: bool,
    /// Subgroup operations in compute shaders (faster scans).
    pub subgroups: bool,
    /// Timestamp queries at compute-pass boundaries (per-stage GPU timings in the bench).
    pub timestamps: bool,
}

impl GpuCapabilities {
    fn from_features(features: wgpu::Features) -> GpuCapabilities {
        GpuCapabilities {
            float32_atomics: features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC),
            subgroups: features.contains(wgpu::Features::SUBGROUP),
            timestamps: features.contains(wgpu::Features::TIMESTAMP_QUERY),
        }
    }
}

/// The optional features we request when the adapter has them (never required).
fn wanted_features() -> wgpu::Features {
    wgpu::Features::SHADER_FLOAT32_ATOMIC
        | wgpu::Features::SUBGROUP
        | wgpu::Features::TIMESTAMP_QUERY
}

/// The device descriptor damage-twin uses for any adapter: the adapter's own limits (eframe's
/// defaults allow only 8 storage buffers per stage, too few for the rasterizer, see STACK.md) and
/// the optional features it supports. The app passes this to `egui_wgpu::WgpuSetupCreateNew`.
pub fn device_descriptor(adapter: &wgpu::Adapter) -> wgpu::DeviceDescriptor<'static> {
    wgpu::DeviceDescriptor {
        label: Some("damage-twin"),
        required_features: adapter.features() & wanted_features(),
        required_limits: adapter.limits(),
        experimental_features: wgpu::ExperimentalFeatures::disabled(),
        memory_hints: wgpu::MemoryHints::Performance,
        trace: wgpu::Trace::Off,
    }
}

/// Rank of an adapter, lower is better: hardware GPUs (discrete, then integrated) before
/// unknown/virtual ones, and the software rasterizers (lavapipe, llvmpipe GL: type `Cpu`) last.
/// Within a type, native backends (Vulkan, Metal, DX12) beat GL, whose compute support is weaker.
pub fn adapter_rank(device_type: wgpu::DeviceType, backend: wgpu::Backend) -> (u8, u8) {
    let device = match device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::Other => 2,
        wgpu::DeviceType::VirtualGpu => 3,
        wgpu::DeviceType::Cpu => 4,
    };
    let backend = match backend {
        wgpu::Backend::Vulkan | wgpu::Backend::Metal | wgpu::Backend::Dx12 => 0,
        wgpu::Backend::BrowserWebGpu => 1,
        _ => 2,
    };
    (device, backend)
}

/// Picks the adapter to use. `DAMAGE_TWIN_ADAPTER=<substring>` forces one by name (e.g.
/// `llvmpipe` to test the software path on a machine with a GPU); otherwise the best
/// [`adapter_rank`]. Works as eframe's `native_adapter_selector` too.
pub fn pick_adapter(adapters: &[wgpu::Adapter]) -> Option<&wgpu::Adapter> {
    if let Ok(wanted) = std::env::var("DAMAGE_TWIN_ADAPTER") {
        let wanted = wanted.to_lowercase();
        if let Some(a) = adapters
            .iter()
            .find(|a| a.get_info().name.to_lowercase().contains(&wanted))
        {
            return Some(a);
        }
    }
    adapters.iter().min_by_key(|a| {
        let info = a.get_info();
        adapter_rank(info.device_type, info.backend)
    })
}

/// A device, its queue and what it can do. Cheap to clone (wgpu handles are reference counted).
#[derive(Clone, Debug)]
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter_info: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    pub capabilities: GpuCapabilities,
    /// Kept so that the instance outlives the device when we created it ourselves.
    _instance: Option<Arc<wgpu::Instance>>,
}

impl GpuContext {
    /// Creates a device on the best adapter (see [`pick_adapter`]). Backends follow
    /// `WGPU_BACKEND` when set (e.g. `vulkan`), else all that are compiled in.
    pub fn new() -> Result<GpuContext, GpuError> {
        pollster::block_on(Self::new_async())
    }

    pub async fn new_async() -> Result<GpuContext, GpuError> {
        Self::create(false).await?.ok_or(GpuError::NoAdapter)
    }

    /// A device on the best adapter when that is a hardware GPU; `None` when the best is a
    /// software rasterizer or there is none (no device is created then).
    pub fn new_hardware() -> Result<Option<GpuContext>, GpuError> {
        pollster::block_on(Self::create(true))
    }

    async fn create(hardware_only: bool) -> Result<Option<GpuContext>, GpuError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
        desc.backends = backends;
        let instance = wgpu::Instance::new(desc);
        let adapters = instance.enumerate_adapters(backends).await;
        let Some(adapter) = pick_adapter(&adapters) else {
            return if hardware_only {
                Ok(None)
            } else {
                Err(GpuError::NoAdapter)
            };
        };
        if hardware_only && adapter.get_info().device_type == wgpu::DeviceType::Cpu {
            return Ok(None);
        }
        let (device, queue) = adapter
            .request_device(&device_descriptor(adapter))
            .await
            .map_err(|e| GpuError::Device(e.to_string()))?;
        let mut ctx = GpuContext::from_device(adapter, device, queue);
        ctx._instance = Some(Arc::new(instance));
        Ok(Some(ctx))
    }

    /// Wraps an existing device (e.g. eframe's `RenderState { adapter, device, queue, .. }`), so
    /// the viewer renders splats on the device that draws the UI. Limits and features are read
    /// from the device, i.e. what it was actually created with.
    pub fn from_device(
        adapter: &wgpu::Adapter,
        device: wgpu::Device,
        queue: wgpu::Queue,
    ) -> GpuContext {
        GpuContext {
            adapter_info: adapter.get_info(),
            limits: device.limits(),
            capabilities: GpuCapabilities::from_features(device.features()),
            device,
            queue,
            _instance: None,
        }
    }

    /// True on a software rasterizer (lavapipe / llvmpipe).
    pub fn is_software(&self) -> bool {
        self.adapter_info.device_type == wgpu::DeviceType::Cpu
    }

    /// One line for logs and the bench: "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)".
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.adapter_info.name, self.adapter_info.backend, self.adapter_info.device_type
        )
    }

    /// Blocks until all submitted work is done (tests, the bench and `render_to_image` only).
    pub fn wait_idle(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Device(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hardware_gpus_rank_before_lavapipe() {
        let lavapipe = adapter_rank(wgpu::DeviceType::Cpu, wgpu::Backend::Vulkan);
        let discrete = adapter_rank(wgpu::DeviceType::DiscreteGpu, wgpu::Backend::Vulkan);
        let integrated_gl = adapter_rank(wgpu::DeviceType::IntegratedGpu, wgpu::Backend::Gl);
        assert!(discrete < integrated_gl);
        assert!(integrated_gl < lavapipe);
        let llvmpipe_gl = adapter_rank(wgpu::DeviceType::Cpu, wgpu::Backend::Gl);
        assert!(lavapipe < llvmpipe_gl, "Vulkan lavapipe before GL llvmpipe");
    }
}
