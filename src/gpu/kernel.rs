//! Small shared helpers for launching compute kernels: building a pipeline from a WGSL file,
//! bind groups from a list of buffers, and dispatch sizes that respect the 65535-per-dimension
//! limit. Kernels themselves live in `shaders/`; nothing stage-specific belongs here.

/// `shaders/common.wgsl` prepended to a stage's own source.
macro_rules! stage_source {
    ($file:literal) => {
        concat!(
            include_str!("../../shaders/common.wgsl"),
            include_str!(concat!("../../shaders/", $file))
        )
    };
}
pub(crate) use stage_source;

/// Threads per workgroup of the 1D kernels (all our 1D kernels use 256).
pub const WORKGROUP: u32 = 256;

/// Builds a compute pipeline for one entry point of a WGSL source, with an automatic layout.
pub fn pipeline(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    entry: &str,
) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module: &module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// Builds all entry points of one WGSL source (one shader module, several pipelines).
pub fn pipelines<const N: usize>(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    entries: [&str; N],
) -> [wgpu::ComputePipeline; N] {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    entries.map(|entry| {
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: None,
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        })
    })
}

/// A binding in a bind group: a whole buffer or a sub-range of one.
pub enum Bind<'a> {
    Buffer(&'a wgpu::Buffer),
    Range(&'a wgpu::Buffer, u64, u64),
    Texture(&'a wgpu::TextureView),
}

/// A bind group for group 0 of `pipeline`, binding `entries` as `(binding, resource)`.
pub fn bind_group(
    device: &wgpu::Device,
    pipeline: &wgpu::ComputePipeline,
    entries: &[(u32, Bind<'_>)],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> = entries
        .iter()
        .map(|(binding, b)| wgpu::BindGroupEntry {
            binding: *binding,
            resource: match b {
                Bind::Buffer(buf) => buf.as_entire_binding(),
                Bind::Range(buf, offset, size) => {
                    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: buf,
                        offset: *offset,
                        size: wgpu::BufferSize::new(*size),
                    })
                }
                Bind::Texture(view) => wgpu::BindingResource::TextureView(view),
            },
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    })
}

/// Workgroup grid for `groups` workgroups: `(x, y)` with `x <= 65535`. Kernels rebuild the
/// linear index as `wg.x + wg.y * num_workgroups.x` and ignore indices past their count.
pub fn grid(groups: u32) -> (u32, u32) {
    const MAX: u32 = 65535;
    if groups <= MAX {
        (groups, 1)
    } else {
        (MAX, groups.div_ceil(MAX))
    }
}

/// Dispatches `groups` workgroups of the currently set pipeline; nothing when `groups` is 0.
pub fn dispatch(pass: &mut wgpu::ComputePass<'_>, groups: u32) {
    if groups > 0 {
        let (x, y) = grid(groups);
        pass.dispatch_workgroups(x, y, 1);
    }
}

/// A uniform buffer for one `T` (written with `queue.write_buffer`).
pub fn uniform<T>(device: &wgpu::Device, label: &str) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: std::mem::size_of::<T>() as u64,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// A storage buffer of `bytes` (at least 16, so empty arrays still bind).
pub fn storage(
    device: &wgpu::Device,
    label: &str,
    bytes: u64,
    extra: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16).next_multiple_of(4),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC
            | extra,
        mapped_at_creation: false,
    })
}
