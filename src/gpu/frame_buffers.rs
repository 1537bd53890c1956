//! The renderer's GPU scratch: per-frame buffers sized by the model capacity, the image and the
//! label count, and the intersection buffers with their tile sort, sized by the intersection
//! capacity.

use super::kernel;
use super::project::{FrameUniforms, PROJECTED_BYTES, tile_bounds};
use super::radix_sort::RadixSort;

/// Per-frame scratch sized by the model capacity, the image size and the label count.
pub(super) struct FrameBuffers {
    pub(super) gaussian_capacity: usize,
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) label_channels: usize,
    pub(super) uniforms: wgpu::Buffer,
    pub(super) projected: wgpu::Buffer,
    pub(super) depth_keys: wgpu::Buffer,
    pub(super) depth_gids: wgpu::Buffer,
    pub(super) labels: wgpu::Buffer,
    pub(super) offsets: wgpu::Buffer,
    pub(super) ranges: wgpu::Buffer,
    pub(super) out_color: wgpu::Buffer,
    pub(super) out_depth: wgpu::Buffer,
    pub(super) out_labels: wgpu::Buffer,
    /// Per pixel (T_final bits, blended count): what the backward pass replays from.
    pub(super) out_state: wgpu::Buffer,
    pub(super) texture: wgpu::Texture,
    pub(super) view: wgpu::TextureView,
}

impl FrameBuffers {
    pub(super) fn new(
        device: &wgpu::Device,
        gaussian_capacity: usize,
        width: u32,
        height: u32,
        label_channels: usize,
    ) -> Self {
        let none = wgpu::BufferUsages::empty();
        let n = gaussian_capacity as u64;
        let pixels = width as u64 * height as u64;
        let [tx, ty] = tile_bounds(width, height);
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("splat render"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        FrameBuffers {
            gaussian_capacity,
            width,
            height,
            label_channels,
            uniforms: kernel::uniform::<FrameUniforms>(device, "frame uniforms"),
            projected: kernel::storage(device, "projected", n * PROJECTED_BYTES, none),
            depth_keys: kernel::storage(device, "depth_keys", n * 4, none),
            depth_gids: kernel::storage(device, "depth_gids", n * 4, none),
            labels: kernel::storage(device, "labels", n * label_channels as u64 * 4, none),
            offsets: kernel::storage(device, "isect_offsets", n * 4, none),
            ranges: kernel::storage(device, "tile_ranges", tx as u64 * ty as u64 * 8, none),
            out_color: kernel::storage(device, "out_color", pixels * 16, none),
            out_depth: kernel::storage(device, "out_depth", pixels * 4, none),
            out_labels: kernel::storage(
                device,
                "out_labels",
                pixels * label_channels as u64 * 4,
                none,
            ),
            out_state: kernel::storage(device, "out_state", pixels * 8, none),
            texture,
            view,
        }
    }
}

/// Intersection buffers and the tile sort, sized by the intersection capacity.
pub(super) struct IsectBuffers {
    pub(super) capacity: u32,
    pub(super) tile_keys: wgpu::Buffer,
    pub(super) isect_gids: wgpu::Buffer,
    pub(super) tile_sort: RadixSort,
}

impl IsectBuffers {
    pub(super) fn new(device: &wgpu::Device, sorter: &RadixSort, capacity: u32) -> IsectBuffers {
        let none = wgpu::BufferUsages::empty();
        IsectBuffers {
            capacity,
            tile_keys: kernel::storage(device, "tile_keys", capacity as u64 * 4, none),
            isect_gids: kernel::storage(device, "isect_gids", capacity as u64 * 4, none),
            tile_sort: sorter.resized(device, capacity),
        }
    }
}
